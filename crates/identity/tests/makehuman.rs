mod common;

use lightfarm_identity::makehuman::bust::{build, Shape, SLOT_CORNEA, SLOT_EYES, SLOT_FACE};
use lightfarm_identity::makehuman::macros::Macros;

fn shape(seed: u64, gender: f64) -> Shape {
    Shape {
        macros: Macros {
            gender,
            age: 0.55,
            muscle: 0.5,
            weight: 0.5,
            ethnicity: [0.2, 0.3, 0.5],
        },
        seed,
        detail_sd: 0.25,
        asymmetry_sd: 0.1,
    }
}

#[test]
fn a_bust_is_built() {
    let t = std::time::Instant::now();
    let m = common::model();
    eprintln!("load {:?}", t.elapsed());
    let t = std::time::Instant::now();
    let b = build(m, &shape(1, 0.0)).unwrap();
    eprintln!("build {:?}", t.elapsed());
    let mesh = &b.mesh;
    eprintln!(
        "{} vertices, {} triangles, {} morphs, {} weights",
        mesh.positions.len(),
        mesh.triangle_count(),
        mesh.morph_targets.len(),
        b.weights.len()
    );
    assert_eq!(mesh.morph_targets.len(), 52);
    assert!(mesh.positions.iter().flatten().all(|x| x.is_finite()));
    assert!(mesh.normals.iter().flatten().all(|x| x.is_finite()));
    for slot in [SLOT_FACE, SLOT_EYES, SLOT_CORNEA] {
        assert!(mesh.triangle_materials.contains(&slot), "slot {slot} empty");
    }
}
