//! MediaPipe's face mesh on lightfarm's TFLite interpreter: the same numbers as TensorFlow
//! Lite on a fixed window of the astronaut (reference written by
//! tests/data/facemesh_reference.py), a mesh that agrees with dlib's landmarks when fitted to
//! the faces dlib finds, a skin mask that holds the cheeks and forehead but not the eyes,
//! eyebrows or mouth, and errors naming a model file that is not a face mesh.

mod common;

use burn::prelude::*;
use lightfarm_face::skin::{is_skin, skin_mask, FACE_OVAL};
use lightfarm_face::{FaceAligner, FaceMesh, Image, Mesh, Roi, MESH_POINTS};

use common::photo;

/// The window of the reference: astronaut.png[14..206, 114..306].
const LEFT: f32 = 114.0;
const TOP: f32 = 14.0;

fn mesh_net() -> FaceMesh {
    FaceMesh::builtin(&Device::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn fitted(name: &str, net: &FaceMesh) -> (Mesh, lightfarm_face::Alignment, image::RgbImage) {
    let img = photo(name);
    let image = Image::new(img.as_raw(), img.width() as usize, img.height() as usize).unwrap();
    let aligner = FaceAligner::builtin(&Device::default()).unwrap_or_else(|e| panic!("{e}"));
    let face = aligner.align(&image).expect("dlib finds the face");
    let mesh = net.fit(&image, &face);
    (mesh, face, img)
}

#[test]
fn matches_tensorflow_lite_on_the_astronaut() {
    let text = include_str!("data/facemesh_astronaut.txt");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let logit: f32 = lines.next().unwrap().trim().parse().unwrap();
    let want: Vec<[f32; 3]> = lines
        .map(|l| {
            let v: Vec<f32> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    assert_eq!(want.len(), MESH_POINTS);
    let img = photo("astronaut.png");
    let image = Image::new(img.as_raw(), img.width() as usize, img.height() as usize).unwrap();
    // A 192² window on the pixel grid: the crop reads the pixels unresampled.
    let roi = Roi {
        centre: [LEFT + 96.0, TOP + 96.0],
        side: 192.0,
        angle: 0.0,
    };
    let mesh = mesh_net().in_roi(&image, roi);
    let mut worst = 0f32;
    for (got, want) in mesh.points.iter().zip(&want) {
        let d = [
            got[0] - LEFT - want[0],
            got[1] - TOP - want[1],
            got[2] - want[2],
        ];
        worst = d.iter().fold(worst, |m, v| m.max(v.abs()));
    }
    assert!(worst < 0.02, "largest difference from TFLite {worst} px");
    let presence = 1.0 / (1.0 + (-logit).exp());
    assert!(
        (mesh.presence - presence).abs() < 1e-4,
        "presence {} vs {presence}",
        mesh.presence
    );
}

#[test]
fn fitted_mesh_agrees_with_dlib_landmarks() {
    let net = mesh_net();
    for name in ["astronaut.png", "grace_hopper.jpg"] {
        let (mesh, face, _) = fitted(name, &net);
        assert!(mesh.presence > 0.9, "{name}: presence {}", mesh.presence);
        let l = &face.landmarks;
        let span = (l[0][0] - l[2][0]).hypot(l[0][1] - l[2][1]);
        // dlib: image-right eye outer, inner, image-left eye outer, inner; the mesh's
        // numbers for the same corners (the subject's left eye is on the image's right).
        for (k, m) in [263, 362, 33, 133].into_iter().enumerate() {
            let p = mesh.points[m];
            let d = (p[0] - l[k][0]).hypot(p[1] - l[k][1]);
            assert!(
                d < 0.12 * span,
                "{name}: mesh point {m} is {d:.1} px from dlib's landmark {k} (eye span {span:.0})"
            );
        }
    }
}

#[test]
fn skin_holds_cheeks_and_forehead_not_eyes_brows_or_mouth() {
    let net = mesh_net();
    for name in ["astronaut.png", "grace_hopper.jpg"] {
        let (mesh, _, img) = fitted(name, &net);
        let p = |i: usize| mesh.points[i];
        let mid = |a: usize, b: usize| [(p(a)[0] + p(b)[0]) / 2.0, (p(a)[1] + p(b)[1]) / 2.0];
        // Cheeks (subject's right, left), forehead, chin.
        for (what, [x, y]) in [
            ("right cheek", mid(50, 205)),
            ("left cheek", mid(280, 425)),
            ("forehead", [p(151)[0], p(151)[1]]),
            ("chin", mid(152, 17)),
        ] {
            assert!(
                is_skin(&mesh, x, y),
                "{name}: the {what} at ({x:.0}, {y:.0}) is not skin"
            );
        }
        for (what, [x, y]) in [
            ("right eye", mid(159, 145)),
            ("left eye", mid(386, 374)),
            ("mouth", mid(13, 14)),
            ("right eyebrow", mid(105, 52)),
            ("left eyebrow", mid(334, 282)),
        ] {
            assert!(
                !is_skin(&mesh, x, y),
                "{name}: the {what} at ({x:.0}, {y:.0}) is skin"
            );
        }
        let (w, h) = (img.width() as usize, img.height() as usize);
        let skin: f32 = skin_mask(&mesh, w, h).iter().sum();
        let oval: f32 = (0..w * h)
            .filter(|i| {
                let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                lightfarm_face::skin::inside(&mesh, &FACE_OVAL, x, y)
            })
            .count() as f32;
        let share = skin / oval;
        assert!(
            (0.75..0.95).contains(&share),
            "{name}: skin is {share:.2} of the face oval"
        );
    }
}

#[test]
fn a_file_that_is_not_a_face_mesh_is_named() {
    let dir = std::env::temp_dir().join(format!("lightfarm-face-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let real = std::fs::read(lightfarm_face::builtin_face_mesh()).unwrap();
    let cases = [
        (
            "empty.tflite",
            Vec::new(),
            "not a TensorFlow Lite flatbuffer",
        ),
        (
            "text.tflite",
            b"a face mesh, honestly".to_vec(),
            "not a TensorFlow Lite flatbuffer",
        ),
        (
            "half.tflite",
            real[..real.len() / 2].to_vec(),
            "not a TensorFlow Lite flatbuffer",
        ),
    ];
    for (file, bytes, says) in cases {
        let path = dir.join(file);
        std::fs::write(&path, bytes).unwrap();
        let e = FaceMesh::load(&path, &Device::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains(file) && e.contains(says), "{file}: {e}");
    }
    let missing = dir.join("missing.tflite");
    let e = FaceMesh::load(&missing, &Device::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("missing.tflite") && e.contains("cannot read"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
