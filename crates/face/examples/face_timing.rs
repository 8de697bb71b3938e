//! Times the face pipeline on the public-domain portraits (BENCHMARKS.md, "Faces"): detection
//! (CNN over the image pyramid), 5-point landmarks, chip cut and the 128-D descriptor, and
//! MediaPipe's face mesh fitted from the landmarks (two 192² crops), each the median of
//! `ROUNDS` runs after one untimed warm-up.
//!
//!   cargo build --workspace --examples && $CARGO_TARGET_DIR/debug/examples/face_timing [ROUNDS]

use std::time::Instant;

use burn::prelude::*;
use lightfarm_face::{builtin_face_net, face_chips, FaceAligner, FaceMesh, FaceNet, Image};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let rounds: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5)
        .max(1);
    let device = Device::default();
    let aligner = FaceAligner::builtin(&device).unwrap_or_else(|e| panic!("{e}"));
    let net = FaceNet::load(&builtin_face_net(), &device).unwrap_or_else(|e| panic!("{e}"));
    let mesh = FaceMesh::builtin(&device).unwrap_or_else(|e| panic!("{e}"));
    println!(
        "photo                 size       detect ms  landmarks ms  chip+descriptor ms  mesh ms"
    );
    for name in ["astronaut.png", "grace_hopper.jpg", "camera.png"] {
        let path = lightfarm_scene::catalog::builtin_assets_dir()
            .join("photos")
            .join(name);
        let img = image::open(&path)
            .unwrap_or_else(|e| panic!("{}: {e}; run ./scripts/fetch-models.sh", path.display()))
            .to_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let view = Image::new(img.as_raw(), w, h).unwrap_or_else(|e| panic!("{e}"));
        let mut planar = vec![0f32; 3 * w * h];
        for (i, p) in img.pixels().enumerate() {
            for c in 0..3 {
                planar[c * w * h + i] = f32::from(p[c]);
            }
        }
        let tensor = Tensor::<1>::from_floats(planar.as_slice(), &device).reshape([1, 3, h, w]);
        let (mut detect, mut landmarks, mut embed, mut meshes) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for round in 0..=rounds {
            let t = Instant::now();
            let faces = aligner.detect(&view);
            let t_detect = t.elapsed().as_secs_f64() * 1e3;
            let Some(&face) = faces.first() else {
                println!("{name:<21} {w}x{h}    no face found");
                break;
            };
            let t = Instant::now();
            let a = aligner.align_box(&view, face);
            let t_landmarks = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            let d = net.embed(face_chips(tensor.clone(), std::slice::from_ref(&a)));
            let _ = d.into_data();
            let t_embed = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            let m = mesh.fit(&view, &a);
            let t_mesh = t.elapsed().as_secs_f64() * 1e3;
            assert!(m.presence > 0.5, "{name}: the mesh sees no face");
            if round > 0 {
                meshes.push(t_mesh);
                detect.push(t_detect);
                landmarks.push(t_landmarks);
                embed.push(t_embed);
            }
        }
        if !detect.is_empty() {
            println!(
                "{name:<21} {:<10} {:>9.1} {:>13.2} {:>19.1} {:>8.1}",
                format!("{w}x{h}"),
                median(detect),
                median(landmarks),
                median(embed),
                median(meshes)
            );
        }
    }
}
