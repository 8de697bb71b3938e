//! The ICT Face Model's identity modes carried onto MakeHuman's base mesh: they move the face
//! by what they move the ICT face, they leave the shoulders alone, eyeballs and teeth move with
//! their face, and a malformed model file is an error naming the array.

mod common;

use lightfarm_identity::ict::{IctModel, ICT_FILE};
use lightfarm_identity::makehuman::bust::{build, Shape, SLOT_EYES, SLOT_FACE_CENTRE};
use lightfarm_identity::makehuman::macros::Macros;

fn shape(ict: Vec<f64>) -> Shape {
    Shape {
        macros: Macros {
            gender: 0.5,
            age: 0.5,
            muscle: 0.5,
            weight: 0.5,
            ethnicity: [1.0 / 3.0; 3],
        },
        seed: 1,
        detail_sd: 0.0,
        asymmetry_sd: 0.0,
        ict,
    }
}

fn rms(d: &[[f32; 3]]) -> f64 {
    (d.iter()
        .map(|p| p.iter().map(|&x| f64::from(x) * f64::from(x)).sum::<f64>())
        .sum::<f64>()
        / d.len().max(1) as f64)
        .sqrt()
}

/// Each of the first modes displaces the face centre by what it displaces the ICT face's
/// (RMS, in the base mesh's scale) within a factor 1.5, and moves nothing below the neck.
#[test]
fn a_mode_moves_the_face_as_much_as_the_ict_face_and_not_the_shoulders() {
    let m = common::model();
    let face = m
        .ict
        .as_ref()
        .expect("the test model loads the ICT Face Model");
    println!(
        "{} base vertices matched; {} dm per cm",
        face.matches.len(),
        face.scale
    );
    assert!(face.matches.len() > 3000, "{} matches", face.matches.len());
    let neutral = build(m, &shape(vec![])).unwrap();
    // Face-centre vertices of the bust, by base-mesh vertex.
    let mut centre = std::collections::BTreeSet::new();
    for (t, tri) in neutral.mesh.indices.chunks_exact(3).enumerate() {
        if neutral.mesh.triangle_materials[t] == SLOT_FACE_CENTRE {
            centre.extend(tri.iter().map(|&i| neutral.source[i as usize]));
        }
    }
    // The ICT face in front of the ears, for its own RMS.
    let ict = &face.model;
    let eyes = ict.centroid(&[ict.eyes[0].clone(), ict.eyes[1].clone()].concat());
    let mut ict_face: Vec<u32> = ict.skin.iter().flatten().copied().collect();
    ict_face.sort_unstable();
    ict_face.dedup();
    ict_face.retain(|&i| {
        let p = ict.neutral[i as usize];
        (-14.5..7.5).contains(&(p[1] - eyes[1])) && p[0].abs() < 7.5 && p[2] > eyes[2] - 3.5
    });
    for mode in 0..4 {
        let mut c = vec![0.0; mode + 1];
        c[mode] = 1.0;
        let offsets = face.offsets(&c).unwrap();
        let by_vertex: std::collections::BTreeMap<u32, [f32; 3]> = offsets.into_iter().collect();
        let ours: Vec<[f32; 3]> = centre
            .iter()
            .map(|v| by_vertex.get(v).copied().unwrap_or([0.0; 3]))
            .collect();
        let theirs: Vec<[f32; 3]> = ict_face
            .iter()
            .map(|&i| ict.modes[mode][i as usize].map(|x| x * face.scale))
            .collect();
        let (a, b) = (rms(&ours), rms(&theirs));
        println!(
            "mode {mode}: face centre RMS {:.3} mm, ICT face {:.3} mm",
            a * 100.0,
            b * 100.0
        );
        assert!(
            a > b / 1.5 && a < b * 1.5,
            "mode {mode}: {a} dm on the base mesh against {b} dm on the ICT face"
        );
        // From 17 cm below the eyes nothing moves: the neck at the collar and the shoulders,
        // and so the garment's fit, are MakeHuman's.
        let eye_y = ["helper-l-eye", "helper-r-eye"]
            .iter()
            .flat_map(|g| m.base.vertices_of(g))
            .map(|v| m.base.positions[v as usize][1])
            .sum::<f32>()
            / ["helper-l-eye", "helper-r-eye"]
                .iter()
                .map(|g| m.base.vertices_of(g).len())
                .sum::<usize>() as f32;
        let low = by_vertex
            .iter()
            .filter(|(v, d)| {
                m.base.positions[**v as usize][1] < eye_y - 1.7 && d.iter().any(|x| *x != 0.0)
            })
            .count();
        assert_eq!(
            low, 0,
            "mode {mode} moves {low} vertices 17 cm below the eyes"
        );
    }
    // The bust's eyes move with the face: with strong coefficients the eyeballs stay centred
    // in their sockets (the eyelid vertices around them) within a millimetre.
    let strong: Vec<f64> = (0..10)
        .map(|k| if k % 2 == 0 { 2.0 } else { -2.0 })
        .collect();
    let moved = build(m, &shape(strong)).unwrap();
    let eye_centre = |b: &lightfarm_identity::makehuman::bust::Bust, right: bool| {
        let mut c = [0.0f64; 3];
        let mut n = 0.0;
        for (t, tri) in b.mesh.indices.chunks_exact(3).enumerate() {
            if b.mesh.triangle_materials[t] != SLOT_EYES {
                continue;
            }
            for &i in tri {
                let p = b.mesh.positions[i as usize];
                if (p[0] > 0.0) == right {
                    for k in 0..3 {
                        c[k] += f64::from(p[k]);
                    }
                    n += 1.0;
                }
            }
        }
        c.map(|x| x / n)
    };
    let lids = |b: &lightfarm_identity::makehuman::bust::Bust, right: bool| {
        // The skin vertices within 2 cm of the neutral eye centre.
        let e = eye_centre(&neutral, right);
        let mut c = [0.0f64; 3];
        let mut n = 0.0;
        for (i, p) in neutral.mesh.positions.iter().enumerate() {
            let d: f64 = (0..3)
                .map(|k| (f64::from(p[k]) - e[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            let s = neutral.source[i];
            if d < 0.02 && s < lightfarm_identity::makehuman::bust::EYE_BASE {
                let q = b.mesh.positions[i];
                for k in 0..3 {
                    c[k] += f64::from(q[k]);
                }
                n += 1.0;
            }
        }
        c.map(|x| x / n)
    };
    for right in [false, true] {
        let shift = |x: [f64; 3], y: [f64; 3]| [0, 1, 2].map(|k| x[k] - y[k]);
        let eye = shift(eye_centre(&moved, right), eye_centre(&neutral, right));
        let lid = shift(lids(&moved, right), lids(&neutral, right));
        let gap = (0..3)
            .map(|k| (eye[k] - lid[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        println!("eye at x>0 {right}: eyeball moved {eye:?} m, its lids {lid:?} m");
        assert!(gap < 1e-3, "the eyeball moved {gap} m away from its lids");
    }
}

/// A file that is not the model, or lacks an array, is an error naming the file and array.
#[test]
fn a_malformed_model_file_is_named() {
    let dir = std::env::temp_dir().join(format!("lightfarm-ict-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let junk = dir.join("junk.npz");
    std::fs::write(&junk, b"not a zip").unwrap();
    let e = IctModel::load(&junk).unwrap_err().to_string();
    assert!(e.contains("junk.npz") && e.contains("not an npz"), "{e}");
    // A real npz without the identity modes: the MakeHuman targets are one.
    let targets = common::assets().join(lightfarm_identity::makehuman::TARGETS_FILE);
    let e = IctModel::load(&targets).unwrap_err().to_string();
    assert!(e.contains("neutral") && e.contains("missing"), "{e}");
    let e = IctModel::load(&dir.join("absent.npz"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("absent.npz") && e.contains("missing"), "{e}");
    // The real file loads.
    let m = IctModel::load(&common::assets().join(ICT_FILE)).unwrap();
    assert_eq!(m.modes.len(), 100);
    std::fs::remove_dir_all(&dir).ok();
}
