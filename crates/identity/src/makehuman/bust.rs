//! A MakeHuman head and shoulders for one shape: macro and face-detail targets applied to the
//! base mesh, the bust cut out, eyes fitted, and the 52 Face Units as morph targets.

use std::collections::BTreeMap;

use lightfarm_render::scene::{Mesh, MorphTarget};
use lightfarm_scene::rng::SampleRng;

use super::macros::{macro_weights, Macros};
use super::obj::{triangles, BaseMesh, Face};
use super::MakeHuman;

/// MakeHuman works in decimetres; scenes are in metres.
const DM_TO_M: f32 = 0.1;

/// Target groups whose modifiers shape a face.
const DETAIL_GROUPS: [&str; 10] = [
    "head", "forehead", "eyebrows", "eyes", "nose", "mouth", "ears", "chin", "cheek", "neck",
];
/// Modifiers left alone: age and scale come from the macros, and moving or tilting the whole
/// head would break the canonical frame the hair and accessories are placed in.
const EXCLUDED: [&str; 6] = [
    "head-age",
    "head-trans",
    "head-scale-vert",
    "head-angle",
    "forehead-scale-vert",
    "neck-trans",
];

/// Material slots of the bust mesh, in [`Mesh::triangle_materials`].
pub const SLOT_FACE: u32 = 0;
pub const SLOT_BODY: u32 = 1;
pub const SLOT_EYES: u32 = 2;
pub const SLOT_CORNEA: u32 = 3;
pub const SLOT_TEETH: u32 = 4;
pub const SLOT_TONGUE: u32 = 5;
/// The face proper (brows to chin, temple to temple; [`crate::skin::maps::FaceUv::face_rect`]),
/// cut out of the head island so it gets a finer texture than the scalp.
pub const SLOT_FACE_CENTRE: u32 = 6;
/// How many slots a bust has.
pub const SLOTS: usize = 7;

/// The head island of hm08's UV layout (face and scalp; OBJ convention), which gets a texture
/// of its own; the face inside it gets a finer one ([`SLOT_FACE_CENTRE`]), and the rest
/// (neck, shoulders, ears) shares a coarser atlas.
pub const HEAD_ISLAND: [[f32; 2]; 2] = [[0.635, 0.135], [0.985, 0.83]];

/// How a person's shape is drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    pub macros: Macros,
    /// Seed of the face-detail weights.
    pub seed: u64,
    /// Standard deviation of each face-detail modifier (MakeHuman slider units, ±1 extreme).
    pub detail_sd: f64,
    /// Standard deviation of the asymmetry modifiers.
    pub asymmetry_sd: f64,
    /// Coefficients of the ICT Face Model's identity modes (first modes first; empty: none),
    /// applied through [`MakeHuman::ict`].
    pub ict: Vec<f64>,
}

/// Detail modifiers are truncated here: beyond it MakeHuman's targets turn into caricature.
const DETAIL_LIMIT: f64 = 0.8;

/// The face-detail target weights for `shape`: every modifier of [`DETAIL_GROUPS`] gets a
/// truncated normal value; a pair `x-decr` / `x-incr` (or `-less`/`-more`, `-in`/`-out`, …)
/// uses one side by the sign; `l-` / `r-` sides share one value so faces stay near-symmetric,
/// and the `asym` group adds the asymmetry. Keyed by target name, sorted.
pub fn detail_weights(model: &MakeHuman, shape: &Shape) -> BTreeMap<String, f64> {
    // Modifier → its targets (one or two), in name order so the draws are stable.
    let mut modifiers: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for name in model.targets.keys() {
        let Some((group, base)) = name.split_once('/') else {
            continue;
        };
        let asym = group == "asym";
        if !(asym || DETAIL_GROUPS.contains(&group)) || EXCLUDED.iter().any(|x| base.starts_with(x))
        {
            continue;
        }
        // Sides share a modifier; the right side is added with the left below.
        if base.starts_with("r-") {
            continue;
        }
        let stem = base.strip_prefix("l-").unwrap_or(base);
        // Opposite ends of one slider share a key; a name without a known end is a slider of
        // its own (`head-oval`, used 0..1).
        let key = match stem.rsplit_once('-') {
            Some((m, end)) => match end {
                "decr" | "incr" | "less" | "more" | "l" | "r" => format!("{group}/{m}"),
                "down" | "up" => format!("{group}/{m}-vert"),
                "backward" | "forward" => format!("{group}/{m}-depth"),
                "in" | "out" => format!("{group}/{m}-horiz"),
                _ => format!("{group}/{stem}"),
            },
            None => format!("{group}/{stem}"),
        };
        modifiers.entry(key).or_default().push(name.clone());
    }
    let mut rng = SampleRng::new(shape.seed, 0, 0);
    let mut out = BTreeMap::new();
    for (key, mut names) in modifiers {
        names.sort();
        let sd = if key.starts_with("asym/") {
            shape.asymmetry_sd
        } else {
            shape.detail_sd
        };
        let v = rng.normal(6.0) * sd;
        let v = v.clamp(-DETAIL_LIMIT, DETAIL_LIMIT);
        // One target: a one-sided shape (head-oval), used with |v|. Two: decr/incr by sign.
        let (target, w) = match names.as_slice() {
            [one] => (one.clone(), v.abs()),
            [lo, hi, ..] => (if v < 0.0 { lo.clone() } else { hi.clone() }, v.abs()),
            [] => continue,
        };
        if w < 1e-3 {
            continue;
        }
        let right = target.replacen("/l-", "/r-", 1);
        if right != target && model.targets.contains_key(&right) {
            out.insert(right, w);
        }
        out.insert(target, w);
    }
    out
}

/// Target name → weight.
pub type TargetWeights = BTreeMap<String, f64>;

/// The base mesh's vertices with the macros and details applied (decimetres), and every
/// target weight used.
pub fn shaped_positions(
    model: &MakeHuman,
    shape: &Shape,
) -> Result<(Vec<[f32; 3]>, TargetWeights), String> {
    let mut weights = macro_weights(&shape.macros);
    weights.extend(detail_weights(model, shape));
    let mut v = model.base.positions.clone();
    for (name, &w) in &weights {
        // The eight empty macro targets of the compiled set (e.g. the average universal one)
        // are absent or empty; both mean "no offset".
        if let Some(t) = model.targets.get(name) {
            t.apply(&mut v, w as f32)
                .map_err(|reason| format!("target {name}: {reason}"))?;
        }
    }
    if !shape.ict.is_empty() {
        let face = model.ict.as_ref().ok_or(
            "the shape has ICT face-shape coefficients but the ICT Face Model was not loaded",
        )?;
        for (i, d) in face.offsets(&shape.ict)? {
            let p = v
                .get_mut(i as usize)
                .ok_or_else(|| format!("the ICT match names base vertex {i}"))?;
            for k in 0..3 {
                p[k] += d[k];
            }
        }
    }
    Ok((v, weights))
}

fn centroid(v: &[[f32; 3]], idx: &[u32]) -> [f32; 3] {
    let mut c = [0.0f64; 3];
    for &i in idx {
        for k in 0..3 {
            c[k] += f64::from(v[i as usize][k]);
        }
    }
    c.map(|x| (x / idx.len().max(1) as f64) as f32)
}

/// A bust mesh before materials: [`SLOTS`] slots (`SLOT_*`), UVs of the head slots already in their
/// head-island texture's frame, glTF V (row 0 at the top).
#[derive(Clone, Debug)]
pub struct Bust {
    pub mesh: Mesh,
    /// Origin of the canonical frame in the base mesh (the head joint), decimetres.
    pub origin_dm: [f32; 3],
    /// Every target weight that shaped it.
    pub weights: BTreeMap<String, f64>,
    /// Per mesh vertex, the vertex it is a copy of: base-mesh numbers, eye-mesh vertex k as
    /// `EYE_BASE + k`.
    pub source: Vec<u32>,
}

struct Builder {
    mesh: Mesh,
    /// (base vertex, uv index, slot) → mesh vertex.
    index: BTreeMap<(u32, u32, u32), u32>,
    /// Base-mesh vertex of each mesh vertex (eye vertices: their eye-mesh vertex + `EYE_BASE`).
    source: Vec<u32>,
}

pub const EYE_BASE: u32 = 1 << 24;

impl Builder {
    fn vertex(&mut self, v: u32, t: u32, slot: u32, pos: [f32; 3], uv: [f32; 2]) -> u32 {
        let next = self.mesh.positions.len() as u32;
        *self.index.entry((v, t, slot)).or_insert_with(|| {
            self.mesh.positions.push(pos);
            self.mesh.uvs.push(uv);
            self.source.push(v);
            next
        })
    }

    fn face(
        &mut self,
        face: &Face,
        slot: u32,
        pos: &dyn Fn(u32) -> [f32; 3],
        uv: &dyn Fn(u32) -> [f32; 2],
        key_base: u32,
    ) {
        for tri in triangles(face) {
            for (v, t) in tri {
                let i = self.vertex(v + key_base, t, slot, pos(v), uv(t));
                self.mesh.indices.push(i);
            }
            self.mesh.triangle_materials.push(slot);
        }
    }
}

fn in_island(uv: [f32; 2]) -> bool {
    in_rect(uv, HEAD_ISLAND)
}

/// Maps an OBJ UV inside [`HEAD_ISLAND`] to the island texture's glTF UV.
pub fn island_uv(uv: [f32; 2]) -> [f32; 2] {
    rect_uv(uv, HEAD_ISLAND)
}

/// Maps an OBJ UV inside `rect` to that rectangle's texture (glTF UV).
pub fn rect_uv(uv: [f32; 2], rect: [[f32; 2]; 2]) -> [f32; 2] {
    let [[u0, v0], [u1, v1]] = rect;
    [(uv[0] - u0) / (u1 - u0), 1.0 - (uv[1] - v0) / (v1 - v0)]
}

fn in_rect(uv: [f32; 2], rect: [[f32; 2]; 2]) -> bool {
    let [[u0, v0], [u1, v1]] = rect;
    (u0..=u1).contains(&uv[0]) && (v0..=v1).contains(&uv[1])
}

/// Builds the bust of `shape`. An error is a reason naming the target, joint or proxy at fault
/// (the caller names the identity); a model that passed [`MakeHuman::load`]'s checks has none.
pub fn build(model: &MakeHuman, shape: &Shape) -> Result<Bust, String> {
    let (v, weights) = shaped_positions(model, shape)?;
    let base: &BaseMesh = &model.base;
    let joint = |name: &str| -> Result<[f32; 3], String> {
        let idx = base.vertices_of(name);
        if idx.is_empty() {
            return Err(format!("the base mesh has no joint group {name:?}"));
        }
        Ok(centroid(&v, &idx))
    };
    let origin = joint("joint-head")?;
    let spine = joint("joint-spine-1")?;
    let clavicle = joint("joint-l-clavicle")?;
    let shoulder = joint("joint-l-shoulder")?;
    // The cut of the generator the built-in heads came from: a third of the way from the upper
    // spine to the collarbones, and 1.25 shoulder widths sideways (the arms are dropped).
    let y_cut = spine[1] + 0.35 * (clavicle[1] - spine[1]);
    let x_lim = 1.25 * shoulder[0].abs();
    let to_m = |p: [f32; 3]| [0, 1, 2].map(|k| (p[k] - origin[k]) * DM_TO_M);

    let mut b = Builder {
        mesh: Mesh {
            name: "synthetic_head".into(),
            positions: vec![],
            normals: vec![],
            uvs: vec![],
            tangents: vec![],
            indices: vec![],
            triangle_materials: vec![],
            morph_targets: vec![],
        },
        index: BTreeMap::new(),
        source: vec![],
    };
    let body_pos = |i: u32| to_m(v[i as usize]);
    let uv_of = |t: u32| base.uvs.get(t as usize).copied().unwrap_or([0.0, 0.0]);
    for face in base.faces_of("body") {
        if !face.corners.iter().all(|&(i, _)| {
            let p = v[i as usize];
            p[1] > y_cut && p[0].abs() < x_lim
        }) {
            continue;
        }
        let face_rect = model.face_uv.face_rect;
        let centre = face
            .corners
            .iter()
            .all(|&(_, t)| in_rect(uv_of(t), face_rect));
        let island = face.corners.iter().all(|&(_, t)| in_island(uv_of(t)));
        if centre {
            b.face(
                face,
                SLOT_FACE_CENTRE,
                &body_pos,
                &|t| rect_uv(uv_of(t), face_rect),
                0,
            );
        } else if island {
            b.face(face, SLOT_FACE, &body_pos, &|t| island_uv(uv_of(t)), 0);
        } else {
            b.face(
                face,
                SLOT_BODY,
                &body_pos,
                &|t| {
                    let [u, w] = uv_of(t);
                    [u, 1.0 - w]
                },
                0,
            );
        }
    }
    for (group, slot) in [
        ("helper-upper-teeth", SLOT_TEETH),
        ("helper-lower-teeth", SLOT_TEETH),
        ("helper-tongue", SLOT_TONGUE),
    ] {
        for face in base.faces_of(group) {
            // No texture: one UV key per vertex.
            let flat = Face {
                group: face.group,
                corners: face.corners.iter().map(|&(i, _)| (i, 0)).collect(),
            };
            b.face(&flat, slot, &body_pos, &|_| [0.0, 0.0], 0);
        }
    }
    // Eyes: the proxy follows the shaped body; the eye texture's clear texels are the cornea.
    let eyes = model.eye_proxy.fit(&v)?;
    let eye_uv = |t: u32| {
        model
            .eye_mesh
            .uvs
            .get(t as usize)
            .copied()
            .unwrap_or([0.0, 0.0])
    };
    for (face, &clear) in model.eye_mesh.faces.iter().zip(&model.eye_clear) {
        let slot = if clear { SLOT_CORNEA } else { SLOT_EYES };
        b.face(
            face,
            slot,
            &|i| to_m(eyes[i as usize]),
            &|t| {
                let [u, w] = eye_uv(t);
                [u, 1.0 - w]
            },
            EYE_BASE,
        );
    }
    let Builder {
        mut mesh, source, ..
    } = b;
    // Every copy of a base (or eye) vertex is welded to its first copy, as the normals of the
    // unsplit base mesh would be.
    let mut first: BTreeMap<u32, u32> = BTreeMap::new();
    let weld: Vec<u32> = source
        .iter()
        .enumerate()
        .map(|(i, &s)| *first.entry(s).or_insert(i as u32))
        .collect();
    mesh.recompute_normals_welded(&weld);
    mesh.recompute_tangents();
    // Morphed normals are recomputed the same way and stored as deltas, since a mesh's own
    // recomputation (for targets without them) does not know the weld.
    let mut posed = mesh.clone();

    // Face Units: body vertices take the unit's offsets; eyes the refit of the moved body.
    for (name, unit) in &model.face_units {
        let mut moved = v.clone();
        unit.apply(&mut moved, 1.0)
            .map_err(|reason| format!("face unit {name}: {reason}"))?;
        let moved_eyes = model.eye_proxy.fit(&moved)?;
        let deltas: Vec<[f32; 3]> = source
            .iter()
            .map(|&s| {
                let (a, b) = if s >= EYE_BASE {
                    let k = (s - EYE_BASE) as usize;
                    (eyes[k], moved_eyes[k])
                } else {
                    (v[s as usize], moved[s as usize])
                };
                [0, 1, 2].map(|k| (b[k] - a[k]) * DM_TO_M)
            })
            .collect();
        for (p, (q, d)) in posed
            .positions
            .iter_mut()
            .zip(mesh.positions.iter().zip(&deltas))
        {
            *p = [q[0] + d[0], q[1] + d[1], q[2] + d[2]];
        }
        posed.recompute_normals_welded(&weld);
        let normal_deltas = posed
            .normals
            .iter()
            .zip(&mesh.normals)
            .map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
            .collect();
        mesh.morph_targets.push(MorphTarget {
            name: name.clone(),
            position_deltas: deltas,
            normal_deltas,
        });
    }
    Ok(Bust {
        mesh,
        origin_dm: origin,
        weights,
        source,
    })
}
