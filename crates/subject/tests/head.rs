//! Heads in the canonical frame: landmarks, expressions, garment placement and headsets on
//! every head of the built-in pack.

use std::collections::BTreeMap;

use glam::Vec3;
use lightfarm_render::scene::Scene;
use lightfarm_scene::{AssetKind, Catalog};
use lightfarm_subject::garment::{Body, CoverMap, GarmentFit};
use lightfarm_subject::headset::fit_headset;
use lightfarm_subject::{Head, Landmarks, SubjectError};

fn catalog() -> Catalog {
    Catalog::builtin().unwrap_or_else(|e| panic!("catalog: {e}"))
}

fn load(
    catalog: &Catalog,
    id: &str,
    weights: &BTreeMap<String, f64>,
) -> Result<Head, SubjectError> {
    let asset = catalog
        .get(id)
        .unwrap_or_else(|| panic!("{id} not in the catalog"));
    Head::load(asset, &catalog.path_of(asset), weights)
}

fn heads(catalog: &Catalog) -> Vec<Head> {
    catalog
        .of_kind(AssetKind::Head)
        .iter()
        .map(|a| load(catalog, &a.id, &BTreeMap::new()).unwrap_or_else(|e| panic!("{}: {e}", a.id)))
        .collect()
}

/// Anatomical sanity of a landmark set, in metres.
fn check_landmarks(id: &str, lm: &Landmarks) {
    assert!(
        lm.eye_left.x > 0.0 && lm.eye_right.x < 0.0,
        "{id}: left eye on +X: {lm:?}"
    );
    let ipd = lm.eye_distance();
    assert!((0.05..0.075).contains(&ipd), "{id}: eye distance {ipd}");
    assert!(
        (lm.eye_left.y - lm.eye_right.y).abs() < 0.004,
        "{id}: eyes level"
    );
    let ear_span = lm.ear_left.x - lm.ear_right.x;
    assert!(
        (0.13..0.22).contains(&ear_span),
        "{id}: ear span {ear_span}"
    );
    assert!(
        lm.ear_left.z < lm.eye_left.z - 0.05,
        "{id}: ears behind the eyes"
    );
    assert!(
        lm.nose_bridge.z > lm.eye_centre().z + 0.01,
        "{id}: bridge in front of the eyes"
    );
    assert!(lm.nose_bridge.x.abs() < 0.01, "{id}: bridge on the midline");
    let above = lm.crown.y - lm.eye_centre().y;
    assert!(
        (0.08..0.16).contains(&above),
        "{id}: crown {above} m above the eyes"
    );
}

#[test]
fn every_head_has_plausible_landmarks_in_the_canonical_frame() {
    let catalog = catalog();
    let heads = heads(&catalog);
    assert_eq!(heads.len(), 11);
    for head in &heads {
        check_landmarks(&head.id, &head.landmarks);
        // The face looks down +Z: the skin's frontmost point is near the midline, in front of
        // the eyes.
        let front = head
            .surface
            .positions
            .iter()
            .max_by(|a, b| a.z.total_cmp(&b.z))
            .copied()
            .unwrap_or_default();
        assert!(
            front.x.abs() < 0.02 && front.z > head.landmarks.eye_centre().z,
            "{}: front {front}",
            head.id
        );
        // Skin lies in front of each eyeball centre (eyelids/cornea), 5-30 mm away.
        for eye in [head.landmarks.eye_left, head.landmarks.eye_right] {
            let ahead = head
                .surface
                .positions
                .iter()
                .filter(|p| {
                    (p.x - eye.x).abs() < 0.006 && (p.y - eye.y).abs() < 0.006 && p.z > eye.z
                })
                .map(|p| p.z - eye.z)
                .fold(f32::INFINITY, f32::min);
            assert!(
                (0.0..0.03).contains(&ahead),
                "{}: eyelid {ahead} m in front of {eye}",
                head.id
            );
        }
    }
}

#[test]
fn the_scan_is_scaled_to_metres() {
    let catalog = catalog();
    let head = load(&catalog, "lee_perry_smith", &BTreeMap::new()).expect("scan");
    let lm = head.landmarks;
    let (lo, hi) = head.surface.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    // The catalog's crown is the scan's highest point after the frame transform.
    assert!(
        (hi.y - lm.crown.y).abs() < 0.003,
        "crown {} vs top {}",
        lm.crown.y,
        hi.y
    );
    // Head and shoulders of an adult: < 45 cm wide, face depth < 30 cm.
    assert!(hi.x - lo.x < 0.45 && hi.z - lo.z < 0.3, "bounds {lo} {hi}");
    // The nose bridge landmark lies on the skin (within 4 mm of a vertex).
    let d = head
        .surface
        .positions
        .iter()
        .map(|p| p.distance(lm.nose_bridge))
        .fold(f32::INFINITY, f32::min);
    assert!(d < 0.004, "bridge {d} m from the skin");
}

#[test]
fn expressions_move_the_face_and_bad_ones_are_errors() {
    let catalog = catalog();
    let neutral = load(&catalog, "mh01_f_young_caucasian", &BTreeMap::new()).expect("neutral");
    let jaw = BTreeMap::from([("jawOpen".to_string(), 1.0)]);
    let open = load(&catalog, "mh01_f_young_caucasian", &jaw).expect("jawOpen");
    // Same vertices in the same order: the jaw's vertices move down by centimetres.
    let moved = neutral
        .surface
        .positions
        .iter()
        .zip(&open.surface.positions)
        .map(|(a, b)| a.y - b.y)
        .fold(0.0, f32::max);
    assert!(moved > 0.01, "jawOpen lowers the jaw by {moved} m");
    // Eyes are landmarks of the skull: an expression does not move them.
    assert!(neutral.landmarks.eye_left.distance(open.landmarks.eye_left) < 0.002);

    let bad = BTreeMap::from([("jawOpenWide".to_string(), 1.0)]);
    let err = load(&catalog, "mh01_f_young_caucasian", &bad).expect_err("unknown morph");
    assert!(err.to_string().contains("jawOpenWide"), "{err}");
    let err = load(&catalog, "ict_seed7_1", &jaw).expect_err("head without morphs");
    let text = err.to_string();
    assert!(
        text.contains("ict_seed7_1") && text.contains("morph"),
        "{text}"
    );
}

fn scene_triangles(scene: &Scene, transform: glam::Mat4) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        let m = transform * inst.transform;
        for t in mesh.indices.chunks_exact(3) {
            out.push(
                t.iter()
                    .map(|&v| m.transform_point3(Vec3::from(mesh.positions[v as usize])))
                    .collect::<Vec<_>>()
                    .try_into()
                    .expect("3"),
            );
        }
    }
    out
}

#[test]
fn garments_sit_on_every_neck() {
    let catalog = catalog();
    let heads = heads(&catalog);
    for garment in catalog.of_kind(AssetKind::Garment) {
        let fitted_to = garment.tags.get("fitted_to").expect("fitted_to tag");
        let body_head = heads
            .iter()
            .find(|h| &h.id == fitted_to)
            .expect("fitted_to head");
        let body = Body::measure(&body_head.surface, &body_head.landmarks).expect("fitted body");
        let scene = Scene::load_gltf(&catalog.path_of(garment)).expect("garment");
        let collar = |tris: &[[Vec3; 3]]| {
            let top = tris
                .iter()
                .flatten()
                .map(|p| p.y)
                .fold(f32::NEG_INFINITY, f32::max);
            let ring: Vec<Vec3> = tris
                .iter()
                .flatten()
                .filter(|p| p.y > top - 0.02)
                .copied()
                .collect();
            let centre = ring.iter().copied().sum::<Vec3>() / ring.len() as f32;
            let half = ring
                .iter()
                .map(|p| (p.x - centre.x).abs())
                .fold(0.0, f32::max);
            (centre, half, top)
        };
        let (c0, half0, _) = collar(&scene_triangles(&scene, glam::Mat4::IDENTITY));
        // On its own body the collar is wider than the neck.
        assert!(
            half0 > body.neck.half_width,
            "{}: collar {half0} vs neck {}",
            garment.id,
            body.neck.half_width
        );
        for head in &heads {
            let Some(target) = Body::measure(&head.surface, &head.landmarks) else {
                // Only the ICT FaceKit heads stop at the throat.
                assert!(head.id.starts_with("ict_"), "{}: no neck", head.id);
                continue;
            };
            let fit = GarmentFit::new(&body, &target);
            let mut warped = scene.clone();
            fit.warp_scene(&mut warped);
            let tris = scene_triangles(&warped, glam::Mat4::IDENTITY);
            let (c, half, top) = collar(&tris);
            // The collar keeps its place relative to the neck (necklines are lower in front,
            // so its centre is not on the neck axis) and its margin around the neck.
            let expected = fit.apply(c0);
            let off = Vec3::new(c.x - expected.x, 0.0, c.z - expected.z).length();
            assert!(
                off < 0.012,
                "{} on {}: collar {off} m off",
                garment.id,
                head.id
            );
            assert!(
                half > target.neck.half_width,
                "{} on {}: collar {half} narrower than the neck {}",
                garment.id,
                head.id,
                target.neck.half_width
            );
            let below_eyes = head.landmarks.eye_centre().y - top;
            assert!(
                (0.07..0.2).contains(&below_eyes),
                "{} on {}: collar {below_eyes} m below the eyes",
                garment.id,
                head.id
            );
            // The cover map sees the torso under the cloth and not the face.
            let cover = CoverMap::new(fit.body_axis(), &tris);
            let chest = target.neck.inside() - Vec3::new(0.0, 0.1, 0.0);
            assert!(
                cover.covers(chest, 0.0),
                "{} on {}: chest not covered",
                garment.id,
                head.id
            );
            assert!(
                !cover.covers(head.landmarks.nose_bridge, 0.03),
                "face covered"
            );
            // Shoulders: the skin 7 cm under the neck reference is inside the cloth or within 3 cm of it.
            if let Some(w) = target.shoulder_half_width {
                let cloth = tris
                    .iter()
                    .flatten()
                    .filter(|p| (p.y - (target.neck.centre.y - 0.07)).abs() < 0.01)
                    .map(|p| (p.x - target.neck.centre.x).abs())
                    .fold(0.0, f32::max);
                assert!(
                    cloth + 0.03 > w,
                    "{} on {}: shoulders {w} vs cloth {cloth}",
                    garment.id,
                    head.id
                );
            }
        }
    }
}

#[test]
fn headset_cups_rest_on_the_ears_of_every_head() {
    let catalog = catalog();
    let asset = catalog
        .get("headphones_procedural")
        .expect("headphones in the catalog");
    let scene = Scene::load_gltf(&catalog.path_of(asset)).expect("headphones");
    for head in heads(&catalog) {
        let lm = head.landmarks;
        let fit = fit_headset(&scene, &lm).expect("fit");
        let pts: Vec<Vec3> = scene_triangles(&scene, fit).into_iter().flatten().collect();
        let half = pts.iter().map(|p| p.x.abs()).fold(0.0, f32::max);
        let bottom = pts.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
        let top = pts.iter().map(|p| p.y).fold(f32::NEG_INFINITY, f32::max);
        for (side, ear) in [(1.0f32, lm.ear_left), (-1.0, lm.ear_right)] {
            let cup: Vec<Vec3> = pts
                .iter()
                .filter(|p| p.x * side > 0.6 * half && p.y < bottom + 0.55 * (top - bottom))
                .copied()
                .collect();
            let inner = cup.iter().map(|p| p.x.abs()).fold(f32::INFINITY, f32::min);
            // Inner face of the cushion just outside the ear (0-10 mm), cup centred on it.
            let gap = inner - ear.x.abs();
            assert!(
                (-0.002..0.012).contains(&gap),
                "{}: cushion gap {gap}",
                head.id
            );
            let centre = cup.iter().copied().sum::<Vec3>() / cup.len() as f32;
            assert!(
                (centre.z - ear.z).abs() < 0.02 && (centre.y - ear.y).abs() < 0.03,
                "{}: cup at {centre}, ear {ear}",
                head.id
            );
        }
        // The headband passes over the crown, not through it.
        let band = pts
            .iter()
            .filter(|p| p.x.abs() < 0.01)
            .map(|p| p.y)
            .fold(f32::INFINITY, f32::min);
        assert!(
            band > lm.crown.y,
            "{}: headband at {band}, crown {}",
            head.id,
            lm.crown.y
        );
    }
}
