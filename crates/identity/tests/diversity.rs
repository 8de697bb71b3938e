//! Diversity of generated people besides skin tone (that is `people.rs`): the age, gender and
//! ancestry mix the spec asks for, and how much face shapes vary along their first PCA modes,
//! next to the ICT Face Model's identity modes (fitted to light-stage scans of real people)
//! measured over the same part of the face.

mod common;

use std::collections::BTreeMap;

use lightfarm_identity::makehuman::bust::{self, SLOT_FACE_CENTRE};
use lightfarm_identity::person::shape_of;
use lightfarm_scene::identity::{sample_identity, IdentitySpec};
use nalgebra::{DMatrix, SymmetricEigen};

const SEED: u64 = 11;

/// Binomial proportion within 4 standard deviations of `p` (a false alarm ~1 in 16,000).
fn assert_fraction(what: &str, hits: usize, n: usize, p: f64) {
    let f = hits as f64 / n as f64;
    let sd = (p * (1.0 - p) / n as f64).sqrt();
    println!("{what}: {f:.4} (asked {p:.4}, sd {sd:.4})");
    assert!((f - p).abs() < 4.0 * sd, "{what}: {f} of {n}, asked {p}");
}

/// Gender, age and dominant ancestry over 4,000 people follow a non-default `[identity]`: the
/// male fraction and each ancestry's share within 4 sd, ages inside the range and uniform by
/// Kolmogorov-Smirnov at the 1 % level.
#[test]
fn age_gender_and_ancestry_follow_the_spec() {
    let spec = IdentitySpec {
        male_fraction: 0.3,
        age_years: [25.0, 65.0],
        ancestry: [2.0, 1.0, 1.0],
        ..IdentitySpec::default()
    };
    let n = 4000;
    let people: Vec<_> = (0..n).map(|k| sample_identity(&spec, SEED, k)).collect();
    let males = people.iter().filter(|p| p.gender == 1.0).count();
    assert!(people.iter().all(|p| p.gender == 0.0 || p.gender == 1.0));
    assert_fraction("male fraction", males, n as usize, 0.3);
    for (a, name) in ["African", "Asian", "Caucasian"].iter().enumerate() {
        let dominant = people
            .iter()
            .filter(|p| (0..3).all(|b| b == a || p.ancestry[a] > p.ancestry[b]))
            .count();
        assert_fraction(
            &format!("dominant ancestry {name}"),
            dominant,
            n as usize,
            spec.ancestry[a] / 4.0,
        );
    }
    for p in &people {
        assert!((p.ancestry.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        assert!((25.0..=65.0).contains(&p.age_years), "age {}", p.age_years);
    }
    let mut ages: Vec<f64> = people.iter().map(|p| (p.age_years - 25.0) / 40.0).collect();
    ages.sort_by(f64::total_cmp);
    let d = ages
        .iter()
        .enumerate()
        .map(|(i, &x)| (x - i as f64 / n as f64).max((i + 1) as f64 / n as f64 - x))
        .fold(0.0, f64::max);
    let critical = 1.628 / (n as f64).sqrt();
    let deciles: Vec<usize> = (0..10)
        .map(|b| ages.iter().filter(|&&x| (x * 10.0) as usize == b).count())
        .collect();
    println!("age: KS D = {d:.4} (1 % critical {critical:.4}); per 4-year bin {deciles:?}");
    assert!(d < critical, "ages are not uniform on [25, 65]: KS D = {d}");
}

/// Per-mode standard deviation of a set of shapes, as the RMS displacement of a vertex (mm) at
/// one sd along the mode: the eigenvalues of the shapes' covariance (through the Gram matrix;
/// there are far fewer shapes than coordinates), largest first.
fn mode_sds_mm(shapes: &[Vec<[f64; 3]>]) -> Vec<f64> {
    let n = shapes.len();
    let v = shapes[0].len();
    let mut x = DMatrix::<f64>::zeros(n, 3 * v);
    for (i, s) in shapes.iter().enumerate() {
        for (j, p) in s.iter().enumerate() {
            for a in 0..3 {
                x[(i, 3 * j + a)] = p[a];
            }
        }
    }
    let mean = x.row_mean();
    for mut row in x.row_iter_mut() {
        row -= &mean;
    }
    let gram = &x * x.transpose() / (n - 1) as f64;
    let mut eig: Vec<f64> = SymmetricEigen::new(gram)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    eig.sort_by(|a, b| b.total_cmp(a));
    eig.iter().map(|l| (l.max(0.0) / v as f64).sqrt()).collect()
}

/// Translation is not shape: each face is moved to its centroid.
fn centred(mut s: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    let c = s
        .iter()
        .fold([0.0; 3], |c, p| [c[0] + p[0], c[1] + p[1], c[2] + p[2]]);
    let c = c.map(|x| x / s.len() as f64);
    for p in &mut s {
        *p = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
    }
    s
}

/// The face proper of `n` people (brows to chin, temple to temple: the bust's face slot), mm.
fn faces(spec: &IdentitySpec, n: u64) -> Vec<Vec<[f64; 3]>> {
    (0..n)
        .map(|k| {
            let id = sample_identity(spec, SEED, k);
            let b = bust::build(common::model(), &shape_of(&id)).unwrap();
            let mut by_source = BTreeMap::new();
            for (t, tri) in b.mesh.indices.chunks_exact(3).enumerate() {
                if b.mesh.triangle_materials[t] == SLOT_FACE_CENTRE {
                    for &i in tri {
                        let p = b.mesh.positions[i as usize];
                        by_source.insert(b.source[i as usize], p.map(|x| f64::from(x) * 1e3));
                    }
                }
            }
            centred(by_source.into_values().collect())
        })
        .collect()
}

/// The ICT Face Model's identity modes over the same region (the face vertices in the box
/// `face_rect` cuts around the eyes), mm RMS per vertex at one sd: its modes are PCA modes
/// scaled so that coefficients are N(0, 1). Cut to a region the modes are no longer exactly
/// orthogonal, so each one's figure is approximate; their root sum of squares is the region's
/// total sd exactly (the coefficients are independent).
fn ict_mode_sds_mm() -> Vec<f64> {
    let path = common::assets().join("models/ict_face_model_light.npz");
    let mut npz = npyz::npz::NpzArchive::open(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    let neutral: Vec<f32> = npz.by_name("neutral").unwrap().unwrap().into_vec().unwrap();
    let modes: Vec<f32> = npz
        .by_name("identity_modes")
        .unwrap()
        .unwrap()
        .into_vec::<npyz::half::f16>()
        .unwrap()
        .into_iter()
        .map(f32::from)
        .collect();
    let faces: Vec<i32> = npz.by_name("faces").unwrap().unwrap().into_vec().unwrap();
    let material: Vec<i16> = npz
        .by_name("face_material")
        .unwrap()
        .unwrap()
        .into_vec()
        .unwrap();
    let names: Vec<String> = npz
        .by_name("material_names")
        .unwrap()
        .unwrap()
        .into_vec()
        .unwrap();
    let id = |n: &str| names.iter().position(|m| m.trim() == n).unwrap() as i16;
    let v = neutral.len() / 3;
    let p = |i: usize| [neutral[3 * i], neutral[3 * i + 1], neutral[3 * i + 2]].map(f64::from);
    let verts = |mat: i16| -> Vec<usize> {
        let mut s: Vec<usize> = faces
            .chunks_exact(4)
            .zip(&material)
            .filter(|(_, &m)| m == mat)
            .flat_map(|(q, _)| q.iter().filter(|&&i| i >= 0).map(|&i| i as usize))
            .collect();
        s.sort_unstable();
        s.dedup();
        s
    };
    let mut eye = [0.0; 3];
    let irises: Vec<usize> = [verts(id("M_IrisLeft")), verts(id("M_IrisRight"))].concat();
    for &i in &irises {
        for (e, x) in eye.iter_mut().zip(p(i)) {
            *e += x / irises.len() as f64;
        }
    }
    // Centimetres: face_rect's box is -1.45..+0.75 dm about the eyes, |x| < 0.75 dm,
    // in front of 0.35 dm behind them.
    let region: Vec<usize> = verts(id("M_Face"))
        .into_iter()
        .filter(|&i| {
            let q = p(i);
            (-14.5..7.5).contains(&(q[1] - eye[1])) && q[0].abs() < 7.5 && q[2] > eye[2] - 3.5
        })
        .collect();
    assert!(
        region.len() > 1000,
        "ICT face region: {} vertices",
        region.len()
    );
    let mut sds: Vec<f64> = modes
        .chunks_exact(3 * v)
        .map(|m| {
            let d: Vec<[f64; 3]> = region
                .iter()
                .map(|&i| [m[3 * i], m[3 * i + 1], m[3 * i + 2]].map(|x| f64::from(x) * 10.0))
                .collect();
            let d = centred(d);
            (d.iter()
                .map(|q| q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
                .sum::<f64>()
                / d.len() as f64)
                .sqrt()
        })
        .collect();
    sds.sort_by(|a, b| b.total_cmp(a));
    sds
}

fn total(sds: &[f64]) -> f64 {
    sds.iter().map(|s| s * s).sum::<f64>().sqrt()
}

/// Face shapes of 100 people vary along many modes, not one, by amounts of the order of real
/// faces (the ICT Face Model's modes over the same region), and both sources of face shape
/// beyond the macros add variation: MakeHuman's face modifiers (`face_shape_sd`) and the ICT
/// light-stage modes (`ict_shape_sd`).
#[test]
fn face_shapes_vary_along_pca_modes_like_real_faces() {
    let n = 100;
    let ours = mode_sds_mm(&faces(&IdentitySpec::default(), n));
    // The MakeHuman modifiers alone at the spread they need without ICT shapes.
    let no_ict = IdentitySpec {
        ict_shape_sd: 0.0,
        face_shape_sd: 0.25,
        ..IdentitySpec::default()
    };
    let makehuman_only = mode_sds_mm(&faces(&no_ict, n));
    let macro_only = mode_sds_mm(&faces(
        &IdentitySpec {
            face_shape_sd: 0.0,
            asymmetry_sd: 0.0,
            ..no_ict
        },
        n,
    ));
    let ict = ict_mode_sds_mm();
    let show = |s: &[f64]| {
        s.iter()
            .take(8)
            .map(|x| format!("{x:.2}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    println!("mode sd, mm RMS per face vertex (first 8; total over all modes):");
    for (what, sds) in [
        (format!("generated (default spec, {n} people)"), &ours),
        (
            "generated without ICT modes (ict_shape_sd = 0, face_shape_sd = 0.25)".to_owned(),
            &makehuman_only,
        ),
        (
            "generated, macros only (all three sds 0)".to_owned(),
            &macro_only,
        ),
        ("ICT Face Model (100 modes)".to_owned(), &ict),
    ] {
        println!("  {what}: {}; total {:.2}", show(sds), total(sds));
    }
    // Real faces differ by millimetres; a generator whose people all look alike would be far
    // below, one of caricatures far above.
    let ratio = total(&ours) / total(&ict);
    assert!(
        (0.5..2.0).contains(&ratio),
        "total face-shape sd {:.2} mm vs the ICT model's {:.2} mm",
        total(&ours),
        total(&ict)
    );
    // Many directions of variation: the fifth mode still carries a tenth of the first's sd.
    assert!(ours[4] > 0.1 * ours[0], "modes {}", show(&ours));
    // Each source adds variation beyond the others.
    assert!(
        total(&makehuman_only) > 1.1 * total(&macro_only),
        "face_shape_sd adds nothing: {:.2} vs {:.2} mm",
        total(&makehuman_only),
        total(&macro_only)
    );
    assert!(
        total(&ours) > 1.1 * total(&makehuman_only),
        "the ICT modes add nothing: {:.2} vs {:.2} mm",
        total(&ours),
        total(&makehuman_only)
    );
}
