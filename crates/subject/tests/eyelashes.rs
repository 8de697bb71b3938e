//! Eyelid margins and eyelashes on every built-in head: where the margins are, that they
//! follow a blink, and that the lashes grown on them are plausible fibres that never pass
//! through the skin or the eyeball.

use std::collections::BTreeMap;

use glam::Vec3;
use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::{AssetKind, Catalog};
use lightfarm_subject::eyelids::{find_lids, EyeLids};
use lightfarm_subject::hair::grow_eyelashes;
use lightfarm_subject::landmarks::closest_on_triangle;
use lightfarm_subject::{assemble, Head};

fn catalog() -> Catalog {
    Catalog::builtin().unwrap_or_else(|e| panic!("catalog: {e}"))
}

fn load(catalog: &Catalog, id: &str, weights: &BTreeMap<String, f64>) -> Head {
    let asset = catalog
        .get(id)
        .unwrap_or_else(|| panic!("{id} not in the catalog"));
    Head::load(asset, &catalog.path_of(asset), weights).unwrap_or_else(|e| panic!("{id}: {e}"))
}

fn head_ids(catalog: &Catalog) -> Vec<String> {
    catalog
        .of_kind(AssetKind::Head)
        .iter()
        .map(|a| a.id.clone())
        .collect()
}

fn skin_triangles(head: &Head, near: Vec3, radius: f32) -> Vec<[Vec3; 3]> {
    let s = &head.surface;
    s.triangles
        .iter()
        .map(|t| t.map(|v| s.positions[v as usize]))
        .filter(|t| t.iter().any(|p| p.distance(near) < radius))
        .collect()
}

/// Triangles of the eyeballs (sclera, eyes, cornea, iris), canonical frame.
fn eye_triangles(head: &Head) -> Vec<[Vec3; 3]> {
    let sc = &head.scene;
    let mut out = Vec::new();
    for inst in &sc.instances {
        let mesh = &sc.meshes[inst.mesh as usize];
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let name = sc.materials[mesh.triangle_materials[t] as usize]
                .name
                .to_ascii_lowercase();
            let eye = ["sclera", "eyes", "cornea", "iris"]
                .iter()
                .any(|k| name.contains(k));
            if eye && !name.contains("lash") {
                out.push([0, 1, 2].map(|k| {
                    inst.transform
                        .transform_point3(Vec3::from(mesh.positions[tri[k] as usize]))
                }));
            }
        }
    }
    out
}

fn distance_to(tris: &[[Vec3; 3]], p: Vec3) -> f32 {
    tris.iter()
        .map(|t| closest_on_triangle(p, *t).distance(p))
        .fold(f32::INFINITY, f32::min)
}

/// Möller–Trumbore on the segment a→b.
fn segment_hits(a: Vec3, b: Vec3, [p0, p1, p2]: [Vec3; 3]) -> bool {
    let d = b - a;
    let (e1, e2) = (p1 - p0, p2 - p0);
    let h = d.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-14 {
        return false;
    }
    let s = a - p0;
    let u = s.dot(h) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let t = e2.dot(q) / det;
    u >= 0.0 && v >= 0.0 && u + v <= 1.0 && (0.0..=1.0).contains(&t)
}

fn middle(pts: &[Vec3]) -> Vec3 {
    pts[pts.len() / 2]
}

#[test]
fn every_head_with_eyeballs_has_both_lid_margins_where_the_eye_opens() {
    let catalog = catalog();
    for id in head_ids(&catalog) {
        let head = load(&catalog, &id, &BTreeMap::new());
        if head.scene.materials.iter().all(|m| {
            let n = m.name.to_ascii_lowercase();
            !(n.contains("sclera") || n == "eyes")
        }) {
            // The scan has no eyeballs and its lashes are in its texture.
            assert!(head.eyelids.is_empty(), "{id}: lids without eyeballs");
            continue;
        }
        assert_eq!(head.eyelids.len(), 2, "{id}: both eyes' margins");
        for lids in &head.eyelids {
            let EyeLids { side, upper, lower } = lids;
            let eye = if *side > 0.0 {
                head.landmarks.eye_left
            } else {
                head.landmarks.eye_right
            };
            assert!(upper.len() >= 40 && lower.len() >= 40, "{id}: {side}");
            // Medial first: the inner corner is nearer the midline.
            assert!(upper[0].x.abs() < upper[upper.len() - 1].x.abs(), "{id}");
            assert!(lower[0].x.abs() < lower[lower.len() - 1].x.abs(), "{id}");
            let width = upper[0].distance(upper[upper.len() - 1]);
            let gap = middle(upper).y - middle(lower).y;
            eprintln!("{id} {side:+}: opening {width:.4} m wide, {gap:.4} m high");
            assert!(
                (0.016..0.036).contains(&width),
                "{id}: opening {width} m wide"
            );
            let (u, l) = (middle(upper), middle(lower));
            let gap = u.y - l.y;
            assert!((0.004..0.016).contains(&gap), "{id}: lids {gap} m apart");
            assert!(
                u.y > eye.y && l.y < eye.y,
                "{id}: the eye centre between its lids"
            );
            assert!(
                u.z > eye.z && l.z > eye.z,
                "{id}: margins in front of the centre"
            );
            let skin = skin_triangles(&head, eye, 0.03);
            for p in upper.iter().chain(lower) {
                let d = distance_to(&skin, *p);
                assert!(d < 1e-4, "{id}: margin point {p} is {d} m off the skin");
            }
        }
    }
}

#[test]
fn the_margins_close_with_a_blink() {
    let catalog = catalog();
    let id = "mh01_f_young_caucasian";
    let open = load(&catalog, id, &BTreeMap::new());
    let blink = BTreeMap::from([
        ("eyeBlinkLeft".to_string(), 1.0),
        ("eyeBlinkRight".to_string(), 1.0),
    ]);
    let closed = load(&catalog, id, &blink);
    assert_eq!(closed.eyelids.len(), 2);
    for (o, c) in open.eyelids.iter().zip(&closed.eyelids) {
        // The same margin points, carried by the morph.
        assert_eq!(o.upper.len(), c.upper.len());
        assert_eq!(o.lower.len(), c.lower.len());
        let drop = middle(&o.upper).y - middle(&c.upper).y;
        assert!(drop > 0.004, "the upper lid comes down {drop} m");
        let gap = middle(&c.upper).y - middle(&c.lower).y;
        assert!(gap < 0.004, "closed lids {gap} m apart");
    }
    let lashes = grow_eyelashes(&closed.surface, &closed.eyelids, 3);
    // Closed lids press the lashes together: fewer of them clear the other lid's skin.
    assert!(lashes.strand_count() > 120, "{}", lashes.strand_count());
}

#[test]
fn lashes_curl_away_from_the_eye_and_never_cross_skin_or_eyeball() {
    let catalog = catalog();
    for id in ["mh01_f_young_caucasian", "mh07_m_old_mixed", "ict_seed7_1"] {
        let head = load(&catalog, id, &BTreeMap::new());
        let lashes = grow_eyelashes(&head.surface, &head.eyelids, 42);
        lashes.validate().unwrap_or_else(|e| panic!("{id}: {e}"));
        let n = lashes.strand_count();
        assert!((200..=320).contains(&n), "{id}: {n} lashes");
        let eyes = eye_triangles(&head);
        let mut skin = skin_triangles(&head, head.landmarks.eye_left, 0.035);
        skin.extend(skin_triangles(&head, head.landmarks.eye_right, 0.035));
        let (mut up, mut down, mut forward) = (0, 0, 0);
        let (mut uppers, mut lowers) = (0, 0);
        for i in 0..n {
            let (pts, widths) = lashes.strand(i);
            let root = pts[0];
            let tip = pts[pts.len() - 1];
            let length: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
            assert!(
                (0.0015..0.013).contains(&length),
                "{id}: lash {i} {length} m"
            );
            assert!(widths[0] <= 0.00014 && widths[0] >= 0.00006, "{id}: width");
            // Which lid: the nearest margin.
            let near = |m: &[Vec3]| {
                m.windows(2)
                    .map(|w| {
                        let d = w[1] - w[0];
                        let t =
                            ((root - w[0]).dot(d) / d.length_squared().max(1e-12)).clamp(0.0, 1.0);
                        (w[0] + d * t).distance(root)
                    })
                    .fold(f32::MAX, f32::min)
            };
            let (d_up, d_low) = head.eyelids.iter().fold((f32::MAX, f32::MAX), |(a, b), l| {
                (a.min(near(&l.upper)), b.min(near(&l.lower)))
            });
            assert!(
                d_up.min(d_low) < 0.0008,
                "{id}: lash {i} root {} m off the margin",
                d_up.min(d_low)
            );
            if d_up < d_low {
                uppers += 1;
                up += (tip.y > root.y) as usize;
            } else {
                lowers += 1;
                down += (tip.y < root.y) as usize;
            }
            forward += (tip.z > root.z) as usize;
            for w in pts.windows(2) {
                assert!(
                    !skin.iter().any(|t| segment_hits(w[0], w[1], *t)),
                    "{id}: lash {i} crosses the skin"
                );
                assert!(
                    !eyes.iter().any(|t| segment_hits(w[0], w[1], *t)),
                    "{id}: lash {i} enters an eyeball: {pts:?}, segment {w:?}, upper {}",
                    d_up < d_low
                );
            }
        }
        // 110 upper and 50 lower lashes an eye, less those that would cross the skin before
        // half their length.
        eprintln!(
            "{id}: {n} lashes; {up} of {uppers} upper curl up, {down} of {lowers} lower curl \
             down, {forward} point forwards"
        );
        assert!(
            uppers >= 180 && lowers >= 50,
            "{id}: {uppers} upper, {lowers} lower"
        );
        assert!(
            up * 100 >= uppers * 85,
            "{id}: {up} of {uppers} upper lashes curl up"
        );
        assert!(
            down * 100 >= lowers * 60,
            "{id}: {down} of {lowers} lower curl down"
        );
        assert!(
            forward >= n * 95 / 100,
            "{id}: {forward} of {n} point forwards"
        );
    }
}

#[test]
fn lashes_are_a_function_of_the_seed() {
    let catalog = catalog();
    let head = load(&catalog, "mh03_f_old_asian", &BTreeMap::new());
    let a = grow_eyelashes(&head.surface, &head.eyelids, 5);
    let b = grow_eyelashes(&head.surface, &head.eyelids, 5);
    let c = grow_eyelashes(&head.surface, &head.eyelids, 6);
    assert_eq!(a, b);
    assert_ne!(a.points, c.points);
    assert_eq!(grow_eyelashes(&head.surface, &[], 5).strand_count(), 0);
}

#[test]
fn assembled_samples_carry_lash_fibres_instead_of_cards() {
    let catalog = catalog();
    let text = "name = \"lashes\"\nseed = 3\ncount = 4\nwidth = 32\nheight = 32\nspp = 1\n\
                [assets]\nheads = [\"ict_seed7_1\"]\n";
    let spec = DatasetSpec::from_toml_str(text, "lashes.toml")
        .and_then(|s| s.validate(&catalog))
        .unwrap_or_else(|e| panic!("spec: {e}"));
    let sample = expand(&spec, 0).expect("expand");
    let a = assemble(&sample, &catalog).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        a.stats.eyelash_strands >= 280,
        "{}",
        a.stats.eyelash_strands
    );
    let lashes = a
        .scene
        .curves
        .iter()
        .find(|c| c.name == "eyelashes")
        .expect("an eyelashes fibre set");
    let hair = &a.scene.materials[lashes.material as usize];
    assert_eq!(hair.name, "hair", "lashes share the hair's fibre material");
    let cards = a
        .scene
        .materials
        .iter()
        .enumerate()
        .filter(|(_, m)| m.name.eq_ignore_ascii_case("eyelashes"))
        .map(|(k, _)| k as u32)
        .collect::<Vec<_>>();
    let card_triangles: usize = a
        .scene
        .meshes
        .iter()
        .map(|m| {
            m.triangle_materials
                .iter()
                .filter(|t| cards.contains(t))
                .count()
        })
        .sum();
    assert_eq!(card_triangles, 0, "the ICT eyelash cards are gone");
}

#[test]
fn lid_search_errors_name_what_is_missing() {
    let catalog = catalog();
    let head = load(&catalog, "mh01_f_young_caucasian", &BTreeMap::new());
    let centre = head.landmarks.eye_left;
    let err = find_lids(&head.surface, &[], centre, 1.0).expect_err("no eyeball");
    assert!(err.contains("no eyeball triangles"), "{err}");
    // An eyeball with no skin around it: no lids frame it.
    let eye = eye_triangles(&head);
    let bare = lightfarm_subject::HeadSurface::default();
    let err = find_lids(&bare, &eye, centre, 1.0).expect_err("no skin");
    assert!(err.contains("the lids do not frame the eyeball"), "{err}");
    // Skin but the eye search centred far from the eye: nothing visible there.
    let err = find_lids(
        &head.surface,
        &eye,
        centre + Vec3::new(0.0, 0.015, 0.0),
        1.0,
    )
    .expect_err("covered");
    assert!(err.contains("no eyeball visible"), "{err}");
}
