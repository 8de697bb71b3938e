mod common;

use lightfarm_identity::makehuman::bust::{
    build, Shape, SLOT_CORNEA, SLOT_EYES, SLOT_FACE, SLOT_FACE_CENTRE,
};
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
        ict: Vec::new(),
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
    for slot in [SLOT_FACE, SLOT_FACE_CENTRE, SLOT_EYES, SLOT_CORNEA] {
        assert!(mesh.triangle_materials.contains(&slot), "slot {slot} empty");
    }
}

/// Vertices split only for their UVs or their texture (the head island's edge) are one point
/// of the skin: they must share one normal, neutral and under every Face Unit, or the seams
/// shade as creases.
#[test]
fn split_vertices_share_their_normal() {
    let b = build(common::model(), &shape(3, 1.0)).unwrap();
    let mut mesh = b.mesh.clone();
    let check = |mesh: &lightfarm_render::scene::Mesh, what: &str| {
        let mut by_source: std::collections::HashMap<u32, [f32; 3]> = Default::default();
        let mut shared = 0;
        for (s, n) in b.source.iter().zip(&mesh.normals) {
            if let Some(m) = by_source.insert(*s, *n) {
                shared += 1;
                let d = (0..3).map(|k| (m[k] - n[k]).abs()).fold(0.0f32, f32::max);
                assert!(
                    d < 1e-5,
                    "{what}: copies of vertex {s} have normals {m:?} and {n:?}"
                );
            }
        }
        assert!(shared > 100, "{what}: only {shared} split vertices");
    };
    check(&mesh, "neutral");
    let smile: std::collections::BTreeMap<String, f64> = [
        ("mouthSmileLeft".to_owned(), 1.0),
        ("mouthSmileRight".to_owned(), 1.0),
    ]
    .into();
    mesh.apply_morphs(&smile).unwrap();
    check(&mesh, "smiling");
}
