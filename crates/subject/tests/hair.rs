//! Strand hair and eyebrows grown on the real head assets, checked with geometry of our own
//! (a nearest-vertex grid and exact point-triangle distances), not the generator's.

use std::sync::OnceLock;

use glam::Vec3;
use lightfarm_scene::expand::{HairSample, HAIR_RANGES};
use lightfarm_subject::hair::{
    grow_eyebrows, grow_eyelashes, grow_hair, hair_albedo, Strands, HAIR_STYLES,
};
use lightfarm_subject::landmarks::closest_on_triangle;
use lightfarm_subject::{HeadSurface, Landmarks};

const BUDGET_TRIANGLES: usize = 1_200_000;

#[derive(Clone, Copy, Debug, PartialEq)]
enum HeadId {
    Mh01,
    Mh04,
    Ict7,
}

struct Head {
    id: HeadId,
    surface: HeadSurface,
    lm: Landmarks,
    index: SkinIndex,
}

/// Catalog id of each test head.
fn asset_id(id: HeadId) -> &'static str {
    match id {
        HeadId::Mh01 => "mh01_f_young_caucasian",
        HeadId::Mh04 => "mh04_m_middleaged_caucasian",
        HeadId::Ict7 => "ict_seed7_1",
    }
}

/// The head as the assembler loads it: canonical frame, skin surface, detected landmarks.
fn load_head(id: HeadId) -> lightfarm_subject::Head {
    let catalog = lightfarm_scene::Catalog::builtin().expect("catalog");
    let a = catalog.get(asset_id(id)).expect("head in the catalog");
    let head = lightfarm_subject::Head::load(a, &catalog.path_of(a), &Default::default())
        .unwrap_or_else(|e| panic!("{}: {e}", asset_id(id)));
    assert!(
        head.surface.triangles.len() > 1000,
        "{}: too little skin",
        asset_id(id)
    );
    head
}

fn head(id: HeadId) -> &'static Head {
    static HEADS: [OnceLock<Head>; 3] = [OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let slot = match id {
        HeadId::Mh01 => 0,
        HeadId::Mh04 => 1,
        HeadId::Ict7 => 2,
    };
    HEADS[slot].get_or_init(|| {
        let loaded = load_head(id);
        let index = SkinIndex::new(&loaded.surface);
        Head {
            id,
            surface: loaded.surface,
            lm: loaded.landmarks,
            index,
        }
    })
}

fn sample(style: &str, density: f64, length_m: f64, curl: f64, clumping: f64) -> HairSample {
    HairSample {
        style: style.to_string(),
        melanin: 0.5,
        melanin_redness: 0.3,
        density,
        length_m,
        curl,
        clumping,
        seed: 0,
        longitudinal_roughness: 0.3,
        azimuthal_roughness: 0.3,
    }
}

/// Mid-range parameters of each style (see `HAIR_RANGES`).
fn typical(style: &str, density: f64) -> HairSample {
    let r = HAIR_RANGES.iter().find(|r| r.style == style).unwrap();
    let mid = |[lo, hi]: [f64; 2]| 0.5 * (lo + hi);
    sample(
        style,
        density,
        mid(r.length_m),
        mid(r.curl),
        mid(r.clumping),
    )
}

/// Grows `samples` on `head` on two threads (the test machine has two cores).
fn grow_all(head: &Head, samples: Vec<HairSample>, seed: u64) -> Vec<(HairSample, Strands)> {
    let (a, b): (Vec<_>, Vec<_>) = samples
        .into_iter()
        .enumerate()
        .partition(|(i, _)| i % 2 == 0);
    let grow = |list: Vec<(usize, HairSample)>| {
        list.into_iter()
            .map(|(i, s)| {
                let strands = grow_hair(&head.surface, &head.lm, &s, seed)
                    .unwrap_or_else(|e| panic!("{:?} {}: {e}", head.id, s.style));
                (i, s, strands)
            })
            .collect::<Vec<_>>()
    };
    let (mut ra, rb) = std::thread::scope(|scope| {
        let hb = scope.spawn(|| grow(b));
        (grow(a), hb.join().unwrap())
    });
    ra.extend(rb);
    ra.sort_by_key(|(i, _, _)| *i);
    ra.into_iter().map(|(_, s, h)| (s, h)).collect()
}

/// Every style at mid-range parameters on MakeHuman head 01 (at 40 % density, to keep the
/// tests fast; the budget test grows full heads).
fn mh01_styles() -> &'static [(HairSample, Strands)] {
    static CELL: OnceLock<Vec<(HairSample, Strands)>> = OnceLock::new();
    CELL.get_or_init(|| {
        let samples = HAIR_STYLES.iter().map(|s| typical(s, 0.4)).collect();
        grow_all(head(HeadId::Mh01), samples, 11)
    })
}

/// A couple of styles on the other two heads.
fn other_heads() -> &'static [(HeadId, HairSample, Strands)] {
    static CELL: OnceLock<Vec<(HeadId, HairSample, Strands)>> = OnceLock::new();
    CELL.get_or_init(|| {
        let mut out = Vec::new();
        for (id, styles) in [
            (HeadId::Mh04, ["short", "long"]),
            (HeadId::Ict7, ["bob", "ponytail"]),
        ] {
            let samples = styles.iter().map(|s| typical(s, 0.25)).collect();
            for (s, h) in grow_all(head(id), samples, 23) {
                out.push((id, s, h));
            }
        }
        out
    })
}

/// All grown sets with their head.
fn all_sets() -> Vec<(&'static Head, &'static HairSample, &'static Strands)> {
    let mut sets: Vec<_> = mh01_styles()
        .iter()
        .map(|(s, h)| (head(HeadId::Mh01), s, h))
        .collect();
    sets.extend(other_heads().iter().map(|(id, s, h)| (head(*id), s, h)));
    sets
}

fn arc(points: &[Vec3]) -> f32 {
    points.windows(2).map(|w| w[0].distance(w[1])).sum()
}

fn mean(values: impl IntoIterator<Item = f32>) -> f32 {
    let (sum, n) = values
        .into_iter()
        .fold((0.0f64, 0usize), |(s, n), v| (s + v as f64, n + 1));
    (sum / n.max(1) as f64) as f32
}

/// The face box of the brief: in front of the ears, between the outer eye corners (eyeball
/// centre ± 1.2 cm) widened by 1.5 cm, from 2 cm below to 3 cm above the eye line.
fn in_face_box(lm: &Landmarks, p: Vec3) -> bool {
    let mid_x = 0.5 * (lm.ear_left.x + lm.ear_right.x);
    let half = 0.5 * (lm.eye_left.x - lm.eye_right.x) + 0.012 + 0.015;
    let eye_y = lm.eye_centre().y;
    p.z > lm.ear_left.z.min(lm.ear_right.z)
        && (p.x - mid_x).abs() < half
        && p.y > eye_y - 0.02
        && p.y < eye_y + 0.03
}

#[test]
fn every_style_validates_and_fits_the_triangle_budget_at_its_longest() {
    let h = head(HeadId::Mh01);
    let samples = HAIR_RANGES
        .iter()
        .map(|r| sample(r.style, 1.0, r.length_m[1], r.curl[1], r.clumping[1]))
        .collect();
    for (s, strands) in grow_all(h, samples, 3) {
        strands.validate().unwrap();
        // Two ribbon triangles a segment (`ribbons_face_the_eye` checks the mesh itself).
        let triangles = 2 * strands.segment_count();
        assert!(
            triangles <= BUDGET_TRIANGLES,
            "{}: {triangles} ribbon triangles",
            s.style
        );
        assert!(
            strands.strand_count() > 5000,
            "{}: {}",
            s.style,
            strands.strand_count()
        );
        for i in 0..strands.strand_count() {
            let n = strands.strand(i).0.len();
            assert!(
                (2..=57).contains(&n),
                "{}: strand {i} has {n} points",
                s.style
            );
        }
    }
}

#[test]
fn every_style_validates_on_every_head() {
    for (h, s, strands) in all_sets() {
        strands.validate().unwrap();
        assert!(strands.strand_count() > 1000, "{:?} {}", h.id, s.style);
        let planned = mean((0..strands.strand_count()).map(|i| strands.strand(i).0.len() as f32));
        assert!(
            planned >= 3.0,
            "{:?} {}: {planned} points per strand",
            h.id,
            s.style
        );
    }
}

#[test]
fn growth_is_deterministic_and_follows_the_seed() {
    let h = head(HeadId::Mh01);
    for style in HAIR_STYLES {
        let s = typical(style, 0.05);
        let a = grow_hair(&h.surface, &h.lm, &s, 5).unwrap();
        let b = grow_hair(&h.surface, &h.lm, &s, 5).unwrap();
        let c = grow_hair(&h.surface, &h.lm, &s, 6).unwrap();
        assert_eq!(bits(&a), bits(&b), "{style}: same seed, different strands");
        assert_ne!(bits(&a).0, bits(&c).0, "{style}: the seed changes nothing");
    }
    let brows = |seed| grow_eyebrows(&h.surface, &h.lm, seed);
    assert_eq!(brows(1), brows(1));
    assert_ne!(brows(1).points, brows(2).points);
}

/// Strands, brows and lashes are grown on rayon's threads; how many there are must not show in
/// a single bit (workers with different core counts must render the same samples).
#[test]
fn growth_does_not_depend_on_the_thread_count() {
    let id = HeadId::Ict7;
    let loaded = load_head(id);
    let h = head(id);
    let pool = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool")
    };
    let grow_all = |threads: usize| {
        pool(threads).install(|| {
            let hair: Vec<Strands> = HAIR_STYLES
                .iter()
                .map(|style| grow_hair(&h.surface, &h.lm, &typical(style, 0.08), 11).unwrap())
                .collect();
            let brows = grow_eyebrows(&h.surface, &h.lm, 11);
            let lashes = grow_eyelashes(&loaded.surface, &loaded.eyelids, 11);
            (hair, brows, lashes)
        })
    };
    let (one, three) = (grow_all(1), grow_all(3));
    assert!(one.1.strand_count() > 0 && one.2.strand_count() > 0);
    for (style, (a, b)) in HAIR_STYLES.iter().zip(one.0.iter().zip(&three.0)) {
        assert!(a.strand_count() > 0, "{style}: no strands");
        assert_eq!(bits(a), bits(b), "{style}: 1 thread and 3 threads differ");
    }
    assert_eq!(
        bits(&one.1),
        bits(&three.1),
        "eyebrows: 1 thread and 3 threads differ"
    );
    assert_eq!(
        bits(&one.2),
        bits(&three.2),
        "eyelashes: 1 thread and 3 threads differ"
    );
}

/// Every coordinate and width as bits, and the offsets: equality here is bit-identity.
fn bits(s: &Strands) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let p: Vec<u32> = s
        .points
        .iter()
        .flat_map(|p| p.to_array())
        .map(f32::to_bits)
        .collect();
    let w: Vec<u32> = s.widths.iter().map(|w| w.to_bits()).collect();
    (p, w, s.offsets.clone())
}

#[test]
fn roots_lie_on_the_scalp() {
    for (h, s, strands) in all_sets() {
        let lm = &h.lm;
        let eye_y = lm.eye_centre().y;
        let ear_z = lm.ear_left.z.max(lm.ear_right.z);
        let face_half = 0.5 * (lm.eye_left.x - lm.eye_right.x) + 0.03;
        for i in 0..strands.strand_count() {
            let r = strands.strand(i).0[0];
            let what = format!("{:?} {} root {i} at {r}", h.id, s.style);
            let d = h.index.signed_distance(r, 0.002);
            assert!(d > 0.0 && d <= 0.001, "{what}: {d} m from the skin");
            assert!(!in_face_box(lm, r), "{what}: on the face");
            // Over the face the hairline is at least 4 cm above the eye line, over the
            // forehead between the eye centres 5 cm.
            if r.z > ear_z + 0.02 && (r.x - lm.nose_bridge.x).abs() < face_half {
                assert!(r.y > eye_y + 0.04, "{what}: below the frontal hairline");
            }
            if r.z > ear_z + 0.02 && r.x < lm.eye_left.x && r.x > lm.eye_right.x {
                assert!(r.y > eye_y + 0.05, "{what}: below the forehead hairline");
            }
            // Nothing below the nape, nothing on the neck or shoulders.
            assert!(r.y > eye_y - 0.085, "{what}: below the nape hairline");
            // Nothing on the pinna (the ear landmark is on its rim).
            for ear in [lm.ear_left, lm.ear_right] {
                assert!(r.distance(ear) > 0.012, "{what}: on the ear");
            }
        }
    }
}

#[test]
fn strands_stay_outside_the_skin() {
    for (h, s, strands) in all_sets() {
        // Roots sit on the flat triangles, which on the coarse MakeHuman scalp (edges up to
        // 3.5 cm) lie up to 4 mm below the nearest vertex's tangent plane; they are checked
        // exactly in `roots_lie_on_the_scalp`.
        let (mut inside, mut deepest, mut total) = (0usize, 0.0f32, 0usize);
        for i in 0..strands.strand_count() {
            for &p in &strands.strand(i).0[1..] {
                total += 1;
                if let Some(height) = h.index.height(p) {
                    if height <= 0.0 {
                        inside += 1;
                        deepest = deepest.min(height);
                    }
                }
            }
        }
        let fraction = inside as f64 / total as f64;
        assert!(
            fraction <= 0.001,
            "{:?} {}: {inside} of {total} points inside the skin",
            h.id,
            s.style
        );
        assert!(
            deepest > -0.003,
            "{:?} {}: a point {deepest} m inside",
            h.id,
            s.style
        );
    }
}

#[test]
fn no_hair_in_front_of_the_face() {
    for (h, s, strands) in all_sets() {
        if let Some(p) = strands.points.iter().find(|p| in_face_box(&h.lm, **p)) {
            panic!(
                "{:?} {}: strand point {p} in front of the face",
                h.id, s.style
            );
        }
    }
}

#[test]
fn mean_arc_length_matches_the_sample() {
    for (h, s, strands) in all_sets() {
        let m = mean((0..strands.strand_count()).map(|i| arc(strands.strand(i).0)));
        let target = s.length_m as f32;
        // The longer styles lose some length where strands end against the shoulders.
        let tolerance = if matches!(s.style.as_str(), "buzz" | "short" | "bob") {
            0.15
        } else {
            0.25
        };
        assert!(
            (m / target - 1.0).abs() <= tolerance,
            "{:?} {}: mean arc {m} for length_m {target}",
            h.id,
            s.style
        );
    }
}

#[test]
fn strand_count_scales_with_density() {
    let h = head(HeadId::Mh01);
    for style in ["buzz", "curly"] {
        let count = |density| {
            grow_hair(&h.surface, &h.lm, &typical(style, density), 11)
                .unwrap()
                .strand_count()
        };
        let ratio = count(0.5) as f64 / count(1.0) as f64;
        assert!(
            (ratio - 0.5).abs() <= 0.025,
            "{style}: density 0.5 gives {ratio} of density 1"
        );
    }
}

#[test]
fn curl_lowers_the_chord_to_arc_ratio() {
    let h = head(HeadId::Mh01);
    let ratio = |s: HairSample| {
        let strands = grow_hair(&h.surface, &h.lm, &s, 9).unwrap();
        mean((0..strands.strand_count()).map(|i| {
            let p = strands.strand(i).0;
            p[0].distance(p[p.len() - 1]) / arc(p)
        }))
    };
    for (style, length, curls) in [
        ("short", 0.06, [0.0, 0.3, 0.3]),
        ("long", 0.4, [0.0, 0.2, 0.4]),
        ("curly", 0.2, [0.6, 0.8, 1.0]),
    ] {
        let r: Vec<f32> = curls
            .iter()
            .map(|&c| ratio(sample(style, 0.05, length, c, 0.0)))
            .collect();
        assert!(
            r[0] > r[2] + 0.01,
            "{style}: chord/arc {r:?} for curl {curls:?}"
        );
        assert!(
            r[0] >= r[1] && r[1] >= r[2],
            "{style}: chord/arc {r:?} for curl {curls:?}"
        );
    }
}

/// Mean horizontal distance from each tip to the centroid of the tips of the strands rooted
/// within 1 cm of its root: the clump it belongs to when strands clump.
fn tip_spread(strands: &Strands) -> f32 {
    let roots: Vec<Vec3> = (0..strands.strand_count())
        .map(|i| strands.strand(i).0[0])
        .collect();
    let tips: Vec<Vec3> = (0..strands.strand_count())
        .map(|i| *strands.strand(i).0.last().unwrap())
        .collect();
    let grid = PointGrid::new(&roots, 0.01);
    mean((0..roots.len()).map(|i| {
        let near = grid.within(&roots, roots[i], 0.01);
        let centre = near.iter().map(|&j| tips[j]).sum::<Vec3>() / near.len() as f32;
        // Across the fall only: tails and long hair vary in length along it.
        (tips[i] - centre).with_y(0.0).length()
    }))
}

#[test]
fn clumping_pulls_tips_together() {
    let h = head(HeadId::Mh01);
    for (style, length) in [
        ("short", 0.06),
        ("long", 0.4),
        ("curly", 0.2),
        ("ponytail", 0.35),
    ] {
        let spread = |clumping| {
            let s = sample(style, 0.1, length, 0.0, clumping);
            tip_spread(&grow_hair(&h.surface, &h.lm, &s, 4).unwrap())
        };
        let (loose, clumped) = (spread(0.0), spread(0.8));
        assert!(
            clumped < 0.8 * loose,
            "{style}: tip spread {clumped} with clumping 0.8, {loose} without"
        );
    }
}

#[test]
fn ponytail_hangs_behind_the_head() {
    for (h, s, strands) in all_sets()
        .into_iter()
        .filter(|(_, s, _)| s.style == "ponytail")
    {
        let behind = (0..strands.strand_count())
            .filter(|&i| strands.strand(i).0.last().unwrap().z < h.lm.crown.z - 0.05)
            .count();
        let fraction = behind as f64 / strands.strand_count() as f64;
        assert!(
            fraction >= 0.99,
            "{:?} {}: only {fraction} of the tips behind the head",
            h.id,
            s.style
        );
        // One tail: the tips are gathered around the midline, not spread over the back.
        let tips_x = mean(
            (0..strands.strand_count())
                .map(|i| (strands.strand(i).0.last().unwrap().x - h.lm.crown.x).abs()),
        );
        assert!(
            tips_x < 0.04,
            "{:?}: tips {tips_x} m from the midline on average",
            h.id
        );
    }
}

#[test]
fn widths_taper_from_root_to_tip() {
    for (h, s, strands) in all_sets() {
        for i in 0..strands.strand_count() {
            let w = strands.strand(i).1;
            assert!(
                w.windows(2).all(|p| p[1] <= p[0]),
                "{:?} {} strand {i}: widths {w:?} grow",
                h.id,
                s.style
            );
            assert!(
                w[0] >= 0.0001 && w[0] <= 0.0003,
                "{:?} {}: root width {}",
                h.id,
                s.style,
                w[0]
            );
        }
        // Full-length strands end at 40 % of their root width.
        let ratios = mean((0..strands.strand_count()).map(|i| {
            let w = strands.strand(i).1;
            w[w.len() - 1] / w[0]
        }));
        assert!(
            (0.35..=0.5).contains(&ratios),
            "{:?} {}: tip/root {ratios}",
            h.id,
            s.style
        );
    }
}

#[test]
fn eyebrows_lie_on_the_brow_ridges() {
    for id in [HeadId::Mh01, HeadId::Mh04, HeadId::Ict7] {
        let h = head(id);
        let brows = grow_eyebrows(&h.surface, &h.lm, 17);
        brows.validate().unwrap();
        let n = brows.strand_count();
        assert!((500..=800).contains(&n), "{id:?}: {n} eyebrow strands");
        let mid_x = 0.5 * (h.lm.ear_left.x + h.lm.ear_right.x);
        let mut per_side = [0usize; 2];
        for i in 0..n {
            let (p, w) = brows.strand(i);
            let root = p[0];
            let (eye, side) = if root.x > mid_x {
                (h.lm.eye_left, 1.0)
            } else {
                (h.lm.eye_right, -1.0)
            };
            per_side[(side < 0.0) as usize] += 1;
            let what = format!("{id:?} brow strand {i} at {root}");
            let above = root.y - eye.y;
            let out = side * (root.x - eye.x);
            assert!(
                (0.008..=0.035).contains(&above),
                "{what}: {above} m above the eye"
            );
            assert!(
                (-0.02..=0.03).contains(&out),
                "{what}: {out} m out from the eye"
            );
            assert!(root.z > eye.z - 0.025, "{what}: behind the brow");
            let len = arc(p);
            assert!((0.004..=0.015).contains(&len), "{what}: length {len}");
            for &q in p {
                assert!(side * (q.x - mid_x) > 0.0, "{what}: crosses the midline");
                let d = h.index.signed_distance(q, 0.003);
                assert!(
                    d > 0.0 && d <= 0.0015,
                    "{what}: point {q} is {d} m off the skin"
                );
            }
            assert!(
                w.windows(2).all(|p| p[1] <= p[0]) && w[0] < 0.0003,
                "{what}: widths {w:?}"
            );
            // Away from the midline and up (the innermost hairs mostly up).
            let dir = p[p.len() - 1] - root;
            assert!(
                side * dir.x > -0.2 * len && dir.y > -0.5 * len,
                "{what}: points {dir}"
            );
        }
        let outward = mean((0..n).map(|i| {
            let p = brows.strand(i).0;
            let side = if p[0].x > mid_x { 1.0 } else { -1.0 };
            side * (p[p.len() - 1].x - p[0].x) / arc(p)
        }));
        assert!(
            outward > 0.5,
            "{id:?}: brow hairs point outwards only {outward} on average"
        );
        assert!(
            per_side.iter().all(|&c| c >= 250),
            "{id:?}: {per_side:?} strands per brow"
        );
    }
}

#[test]
fn ribbons_face_the_eye() {
    let h = head(HeadId::Mh01);
    let mut strands = grow_hair(&h.surface, &h.lm, &typical("curly", 0.05), 2).unwrap();
    strands.extend(&grow_eyebrows(&h.surface, &h.lm, 2));
    let eye = Vec3::new(0.3, 0.2, 1.0);
    let mesh = strands.ribbon_mesh(eye, "hair");
    assert_eq!(mesh.name, "hair");
    assert_eq!(mesh.triangle_count(), 2 * strands.segment_count());
    assert_eq!(mesh.normals.len(), mesh.positions.len());
    assert_eq!(mesh.uvs.len(), mesh.positions.len());
    assert_eq!(mesh.tangents.len(), mesh.positions.len());
    assert_eq!(mesh.triangle_materials, vec![0; mesh.triangle_count()]);
    assert!(mesh.morph_targets.is_empty());
    assert!(mesh
        .indices
        .iter()
        .all(|&i| (i as usize) < mesh.positions.len()));
    let pos = |i: u32| Vec3::from(mesh.positions[i as usize]);
    // Per segment, four vertices: a pair across each end, one width apart, centred on the
    // strand; the normal is perpendicular to the segment and faces the eye.
    assert_eq!(mesh.positions.len(), 4 * strands.segment_count());
    let mut quad = 0usize;
    for i in 0..strands.strand_count() {
        let (p, w) = strands.strand(i);
        for j in 0..p.len() - 1 {
            let k = 4 * quad;
            quad += 1;
            let t = (p[j + 1] - p[j]).normalize();
            let n = Vec3::from(mesh.normals[k]);
            let centre = (p[j] + p[j + 1]) * 0.5;
            assert!(
                (n.length() - 1.0).abs() < 1e-4,
                "segment {i}.{j}: normal length {}",
                n.length()
            );
            assert!(
                n.dot(t).abs() < 1e-3,
                "segment {i}.{j}: normal not perpendicular"
            );
            assert!(
                n.dot((eye - centre).normalize()) >= -1e-6,
                "segment {i}.{j} faces away"
            );
            for (end, point, width) in [(0, p[j], w[j]), (2, p[j + 1], w[j + 1])] {
                let (a, b) = (pos((k + end) as u32), pos((k + end + 1) as u32));
                assert!(
                    ((a - b).length() - width).abs() < 1e-6,
                    "segment {i}.{j}: width"
                );
                assert!(
                    ((a + b) * 0.5).distance(point) < 1e-6,
                    "segment {i}.{j}: centre"
                );
                assert!(
                    (a - b).normalize().dot(t).abs() < 1e-3,
                    "segment {i}.{j}: not across"
                );
            }
            for q in 0..4 {
                assert_eq!(Vec3::from(mesh.normals[k + q]), n);
            }
            let uv = |q: usize| mesh.uvs[k + q];
            assert!(uv(0)[0] == 0.0 && uv(1)[0] == 1.0 && uv(2)[0] == 0.0 && uv(3)[0] == 1.0);
            assert!(uv(0)[1] == uv(1)[1] && uv(2)[1] == uv(3)[1] && uv(0)[1] < uv(2)[1]);
            if j == 0 {
                assert_eq!(uv(0)[1], 0.0);
            }
            if j == p.len() - 2 {
                assert_eq!(uv(2)[1], 1.0);
            }
        }
    }
    // Front faces towards the eye: counter-clockwise winding agrees with the vertex normals.
    for tri in mesh.indices.chunks_exact(3) {
        let (a, b, c) = (pos(tri[0]), pos(tri[1]), pos(tri[2]));
        let g = (b - a).cross(c - a);
        if g.length() > 1e-12 {
            let n = Vec3::from(mesh.normals[tri[0] as usize]);
            assert!(
                g.dot(n) > 0.0,
                "triangle {tri:?} is wound away from its normal"
            );
        }
    }
}

#[test]
fn hair_albedo_darkens_with_melanin_and_reddens_with_redness() {
    for m in [0.0, 0.3, 0.6, 0.9, 1.0] {
        for r in [0.0, 0.5, 1.0] {
            let c = hair_albedo(m, r);
            assert!(
                c.iter().all(|v| *v > 0.0 && *v < 1.0),
                "albedo({m}, {r}) = {c:?}"
            );
        }
    }
    let luminance = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    for r in [0.0, 0.5, 1.0] {
        let mut last = hair_albedo(0.0, r);
        for step in 1..=20 {
            let m = step as f64 / 20.0;
            let c = hair_albedo(m, r);
            assert!(
                luminance(c) < luminance(last) && (0..3).all(|k| c[k] <= last[k]),
                "melanin {m}, redness {r}: {c:?} is not darker than {last:?}"
            );
            last = c;
        }
    }
    for m in [0.2, 0.5, 0.8] {
        let mut last = hair_albedo(m, 0.0);
        for step in 1..=10 {
            let r = step as f64 / 10.0;
            let c = hair_albedo(m, r);
            assert!(
                c[0] / c[1] > last[0] / last[1] && c[0] / c[2] > last[0] / last[2],
                "melanin {m}, redness {r}: {c:?} is not redder than {last:?}"
            );
            last = c;
        }
    }
    // Dark brown, not black, at Blender's default melanin; near-white with no melanin.
    let brown = hair_albedo(0.8, 0.0);
    assert!(brown[0] > 0.05 && brown[0] > 2.0 * brown[2], "{brown:?}");
    assert!(hair_albedo(0.0, 0.0).iter().all(|v| *v > 0.8));
    assert!(hair_albedo(f64::NAN, 2.0).iter().all(|v| v.is_finite()));
}

#[test]
fn bad_hair_parameters_are_errors_that_say_what_is_wrong() {
    let h = head(HeadId::Mh01);
    let mohawk = HairSample {
        style: "mohawk".to_string(),
        ..typical("short", 1.0)
    };
    let err = grow_hair(&h.surface, &h.lm, &mohawk, 1).unwrap_err();
    assert!(err.contains("mohawk"), "{err}");
    for style in HAIR_STYLES {
        assert!(err.contains(style), "{err} does not list {style}");
    }
    for (field, s) in [
        (
            "density",
            HairSample {
                density: 1.5,
                ..typical("short", 1.0)
            },
        ),
        (
            "length_m",
            HairSample {
                length_m: f64::NAN,
                ..typical("short", 1.0)
            },
        ),
        (
            "length_m",
            HairSample {
                length_m: 0.0,
                ..typical("short", 1.0)
            },
        ),
        (
            "curl",
            HairSample {
                curl: -0.1,
                ..typical("short", 1.0)
            },
        ),
        (
            "clumping",
            HairSample {
                clumping: 2.0,
                ..typical("short", 1.0)
            },
        ),
    ] {
        let err = grow_hair(&h.surface, &h.lm, &s, 1).unwrap_err();
        assert!(err.contains(field), "{field}: {err}");
    }
    let empty = grow_hair(&h.surface, &h.lm, &typical("short", 0.0), 1).unwrap();
    assert_eq!(empty.strand_count(), 0);
    empty.validate().unwrap();
    // Landmarks of another head put the scalp in the air: an error, not an empty head.
    let mut far = h.lm;
    for p in [
        &mut far.eye_left,
        &mut far.eye_right,
        &mut far.ear_left,
        &mut far.ear_right,
        &mut far.nose_bridge,
        &mut far.crown,
    ] {
        *p += Vec3::new(0.0, 2.0, 0.0);
    }
    assert!(grow_hair(&h.surface, &far, &typical("short", 1.0), 1).is_err());
    assert!(grow_hair(&HeadSurface::default(), &h.lm, &typical("short", 1.0), 1).is_err());
    assert_eq!(
        grow_eyebrows(&HeadSurface::default(), &h.lm, 1).strand_count(),
        0
    );
}

#[test]
fn strand_sets_check_their_invariants_and_extend() {
    let mut a = Strands::new();
    assert_eq!(a.strand_count(), 0);
    a.validate().unwrap();
    let good = Strands {
        points: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE],
        widths: vec![1e-4; 5],
        offsets: vec![0, 2, 5],
    };
    good.validate().unwrap();
    assert_eq!(good.segment_count(), 3);
    assert_eq!(good.strand(1).0, &[Vec3::Y, Vec3::Z, Vec3::ONE]);
    assert_eq!(good.strand(7).0.len(), 0);
    a.extend(&good);
    a.extend(&good);
    a.validate().unwrap();
    assert_eq!((a.strand_count(), a.segment_count()), (4, 6));
    assert_eq!(a.offsets, vec![0, 2, 5, 7, 10]);
    assert_eq!(a.strand(3).0, good.strand(1).0);

    let broken = |f: &dyn Fn(&mut Strands)| {
        let mut s = good.clone();
        f(&mut s);
        s.validate().unwrap_err()
    };
    assert!(broken(&|s| s.offsets = vec![0, 1, 5]).contains("strand 0"));
    assert!(broken(&|s| s.offsets = vec![0, 4, 3, 5]).contains("decrease"));
    assert!(broken(&|s| s.offsets = vec![1, 2, 5]).contains("start"));
    assert!(broken(&|s| s.offsets = vec![0, 2, 4]).contains("last offset"));
    assert!(broken(&|s| {
        s.widths.pop();
    })
    .contains("widths"));
    assert!(broken(&|s| s.points[3] = Vec3::NAN).contains("point 3"));
    assert!(broken(&|s| s.widths[2] = 0.0).contains("width 2"));
    assert!(broken(&|s| s.widths[2] = f32::INFINITY).contains("width 2"));
    assert!(broken(&|s| s.offsets.clear()).contains("start"));
}

/// Uniform grid over points for radius and nearest queries.
struct PointGrid {
    origin: Vec3,
    cell: f32,
    dims: [i64; 3],
    cells: Vec<Vec<u32>>,
}

impl PointGrid {
    fn new(points: &[Vec3], cell: f32) -> PointGrid {
        let lo = points
            .iter()
            .fold(Vec3::splat(f32::INFINITY), |a, p| a.min(*p))
            - Vec3::splat(cell);
        let hi = points
            .iter()
            .fold(Vec3::splat(f32::NEG_INFINITY), |a, p| a.max(*p))
            + Vec3::splat(cell);
        let d = ((hi - lo) / cell).ceil();
        let dims = [d.x as i64 + 1, d.y as i64 + 1, d.z as i64 + 1];
        let mut grid = PointGrid {
            origin: lo,
            cell,
            dims,
            cells: vec![Vec::new(); (dims[0] * dims[1] * dims[2]) as usize],
        };
        for (i, p) in points.iter().enumerate() {
            let c = grid.cell_of(*p);
            let k = grid.key(c).unwrap();
            grid.cells[k].push(i as u32);
        }
        grid
    }

    fn cell_of(&self, p: Vec3) -> [i64; 3] {
        let c = ((p - self.origin) / self.cell).floor();
        [c.x as i64, c.y as i64, c.z as i64]
    }

    fn key(&self, c: [i64; 3]) -> Option<usize> {
        if (0..3).all(|k| c[k] >= 0 && c[k] < self.dims[k]) {
            Some(((c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]) as usize)
        } else {
            None
        }
    }

    fn cells_around(&self, p: Vec3, r: f32) -> impl Iterator<Item = &Vec<u32>> + '_ {
        let lo = self.cell_of(p - Vec3::splat(r));
        let hi = self.cell_of(p + Vec3::splat(r));
        (lo[2]..=hi[2]).flat_map(move |z| {
            (lo[1]..=hi[1]).flat_map(move |y| {
                (lo[0]..=hi[0]).filter_map(move |x| self.key([x, y, z]).map(|k| &self.cells[k]))
            })
        })
    }

    fn within(&self, points: &[Vec3], p: Vec3, r: f32) -> Vec<usize> {
        self.cells_around(p, r)
            .flatten()
            .map(|&i| i as usize)
            .filter(|&i| points[i].distance(p) <= r)
            .collect()
    }
}

/// Compact grid for exact nearest-vertex queries: scans shells of cells outwards, skipping
/// cells farther than the best match so far.
struct NearestGrid {
    origin: Vec3,
    cell: f32,
    dims: [i64; 3],
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl NearestGrid {
    fn new(points: &[Vec3], cell: f32) -> NearestGrid {
        let lo = points
            .iter()
            .fold(Vec3::splat(f32::INFINITY), |a, p| a.min(*p));
        let hi = points
            .iter()
            .fold(Vec3::splat(f32::NEG_INFINITY), |a, p| a.max(*p));
        let d = ((hi - lo) / cell).floor();
        let dims = [d.x as i64 + 1, d.y as i64 + 1, d.z as i64 + 1];
        let n = (dims[0] * dims[1] * dims[2]) as usize;
        let key = |p: Vec3| {
            let c = ((p - lo) / cell).floor();
            let c = [c.x as i64, c.y as i64, c.z as i64];
            let c: Vec<i64> = (0..3).map(|k| c[k].clamp(0, dims[k] - 1)).collect();
            ((c[2] * dims[1] + c[1]) * dims[0] + c[0]) as usize
        };
        let mut starts = vec![0u32; n + 1];
        for p in points {
            starts[key(*p) + 1] += 1;
        }
        for i in 0..n {
            starts[i + 1] += starts[i];
        }
        let mut fill = starts.clone();
        let mut items = vec![0u32; points.len()];
        for (i, p) in points.iter().enumerate() {
            let k = key(*p);
            items[fill[k] as usize] = i as u32;
            fill[k] += 1;
        }
        NearestGrid {
            origin: lo,
            cell,
            dims,
            starts,
            items,
        }
    }

    /// Nearest point among the cells up to `rings` cells away, and the radius within which
    /// that answer is exact.
    fn scan(&self, points: &[Vec3], p: Vec3, rings: i64) -> (Option<(usize, f32)>, f32) {
        let c = ((p - self.origin) / self.cell).floor();
        let c = [c.x as i64, c.y as i64, c.z as i64];
        // Distance from p to the cells outside the scanned block bounds what it has missed.
        let lo = self.origin
            + Vec3::new(
                (c[0] - rings) as f32,
                (c[1] - rings) as f32,
                (c[2] - rings) as f32,
            ) * self.cell;
        let hi = lo + Vec3::splat((2 * rings + 1) as f32 * self.cell);
        let covered = (p - lo).min(hi - p).min_element().max(0.0);
        let mut best: Option<(usize, f32)> = None;
        for z in (c[2] - rings).max(0)..=(c[2] + rings).min(self.dims[2] - 1) {
            for y in (c[1] - rings).max(0)..=(c[1] + rings).min(self.dims[1] - 1) {
                for x in (c[0] - rings).max(0)..=(c[0] + rings).min(self.dims[0] - 1) {
                    let box_lo = self.origin + Vec3::new(x as f32, y as f32, z as f32) * self.cell;
                    let gap = (box_lo - p)
                        .max(p - box_lo - Vec3::splat(self.cell))
                        .max(Vec3::ZERO);
                    if best.is_some_and(|(_, d)| gap.length() > d) {
                        continue;
                    }
                    let k = ((z * self.dims[1] + y) * self.dims[0] + x) as usize;
                    for &i in &self.items[self.starts[k] as usize..self.starts[k + 1] as usize] {
                        let d = points[i as usize].distance(p);
                        if best.is_none_or(|(_, b)| d < b) {
                            best = Some((i as usize, d));
                        }
                    }
                }
            }
        }
        (best, covered)
    }
}

/// The skin for checking: nearest-vertex heights and exact distances to the triangles.
struct SkinIndex {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[Vec3; 3]>,
    /// Sum of each triangle's vertex normals (outwards).
    triangle_normals: Vec<Vec3>,
    fine: NearestGrid,
    coarse: NearestGrid,
    /// Vertices on an edge used by one triangle only.
    open_edge: Vec<bool>,
    /// Per 5 mm cell, the triangles whose bounding box overlaps it.
    triangle_cells: PointGrid,
}

impl SkinIndex {
    fn new(s: &HeadSurface) -> SkinIndex {
        let triangles: Vec<[Vec3; 3]> = s
            .triangles
            .iter()
            .map(|t| t.map(|i| s.positions[i as usize]))
            .collect();
        let mut triangle_cells = PointGrid::new(&s.positions, 0.005);
        for c in triangle_cells.cells.iter_mut() {
            c.clear();
        }
        for (t, tri) in triangles.iter().enumerate() {
            let lo = triangle_cells.cell_of(tri[0].min(tri[1]).min(tri[2]));
            let hi = triangle_cells.cell_of(tri[0].max(tri[1]).max(tri[2]));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let k = triangle_cells.key([x, y, z]).unwrap();
                        triangle_cells.cells[k].push(t as u32);
                    }
                }
            }
        }
        let triangle_normals = s
            .triangles
            .iter()
            .map(|t| t.iter().map(|&i| s.normals[i as usize]).sum())
            .collect();
        let mut edge_use = std::collections::BTreeMap::new();
        for t in &s.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *edge_use.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let mut open_edge = vec![false; s.positions.len()];
        for ((a, b), uses) in edge_use {
            if uses == 1 {
                open_edge[a as usize] = true;
                open_edge[b as usize] = true;
            }
        }
        SkinIndex {
            open_edge,
            triangle_normals,
            positions: s.positions.clone(),
            normals: s.normals.clone(),
            fine: NearestGrid::new(&s.positions, 0.008),
            coarse: NearestGrid::new(&s.positions, 0.03),
            triangle_cells,
            triangles,
        }
    }

    /// Height above the tangent plane of the nearest skin vertex; `None` when no vertex is
    /// within 4 cm (deeper than the generator looks, so its misses would show here) or the
    /// nearest is on an open edge of the mesh (where a head file cuts the neck, chest or
    /// arms, its normal cannot tell the air beside the cut from the body).
    fn height(&self, p: Vec3) -> Option<f32> {
        let (mut best, covered) = self.fine.scan(&self.positions, p, 2);
        if best.is_none_or(|(_, d)| d > covered) {
            let (coarse, covered) = self.coarse.scan(&self.positions, p, 2);
            assert!(covered >= 0.04 || coarse.is_none_or(|(_, d)| d <= covered));
            best = coarse;
        }
        let (i, d) = best?;
        (d <= 0.04 && !self.open_edge[i]).then(|| (p - self.positions[i]).dot(self.normals[i]))
    }

    /// Exact distance to the skin triangles, negative on the inner side of the nearest one
    /// (by its face normal turned outwards like its vertex normals); `f32::INFINITY` beyond
    /// `max`.
    fn signed_distance(&self, p: Vec3, max: f32) -> f32 {
        let nearest = self
            .triangle_cells
            .cells_around(p, max)
            .flatten()
            .map(|&t| {
                let c = closest_on_triangle(p, self.triangles[t as usize]);
                (t as usize, c, c.distance(p))
            })
            .filter(|(_, _, d)| *d <= max)
            .min_by(|a, b| a.2.total_cmp(&b.2));
        match nearest {
            None => f32::INFINITY,
            Some((t, c, d)) => {
                let [a, b, cc] = self.triangles[t];
                let mut n = (b - a).cross(cc - a).normalize();
                if n.dot(self.triangle_normals[t]) < 0.0 {
                    n = -n;
                }
                if (p - c).dot(n) < 0.0 {
                    -d
                } else {
                    d
                }
            }
        }
    }
}
