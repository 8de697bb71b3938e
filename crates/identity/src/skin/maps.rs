//! A person's skin textures in the MakeHuman UV layout: diffuse albedo from the chromophore
//! model with regional variation, a pore-scale normal map, and roughness/specular maps.
//!
//! Regions come from two sources: MPFB's painted masks (lips, eyelids, ears, face) and
//! Gaussian spots around landmarks found once on the base mesh (cheeks, nose tip, chin,
//! forehead, upper lip), whose UVs every shape shares because targets move vertices, not UVs.
//! Spot radii are in centimetres, turned into UV units by the eye distance in both spaces.

use lightfarm_render::scene::Texture;

use super::chromophore::{AlbedoTable, Chromophores};
use super::noise;
use crate::makehuman::bust::HEAD_ISLAND;
use crate::makehuman::obj::BaseMesh;
use crate::makehuman::MakeHuman;

/// Landmark UVs (OBJ convention) on the base mesh, and the UV length of a centimetre.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaceUv {
    pub cheeks: [[f32; 2]; 2],
    pub nose_tip: [f32; 2],
    pub chin: [f32; 2],
    pub forehead: [f32; 2],
    pub upper_lip: [f32; 2],
    pub brows: [[f32; 2]; 2],
    /// Below each eye, where periorbital darkening sits.
    pub under_eyes: [[f32; 2]; 2],
    pub uv_per_cm: f32,
    /// The face (brows to below the chin, temple to temple) inside the head island: a UV
    /// rectangle ([min, max]) that gets a texture of its own at higher resolution.
    pub face_rect: [[f32; 2]; 2],
}

/// The body vertex with the largest z in a box (x, y ranges in decimetres), and its UV.
fn front_most(base: &BaseMesh, x: [f32; 2], y: [f32; 2]) -> Option<(u32, [f32; 2])> {
    let body = base.group("body")?;
    let mut best: Option<(f32, u32, u32)> = None;
    for f in base.faces.iter().filter(|f| f.group == body) {
        for &(v, t) in &f.corners {
            let p = base.positions[v as usize];
            if p[0] >= x[0]
                && p[0] <= x[1]
                && p[1] >= y[0]
                && p[1] <= y[1]
                && best.is_none_or(|b| p[2] > b.0)
            {
                best = Some((p[2], v, t));
            }
        }
    }
    best.map(|(_, v, t)| (v, base.uvs[t as usize]))
}

/// Padding of the face rectangle, in UV units: triangles at its edge stay inside it.
const FACE_RECT_PAD: f32 = 0.004;

/// The UV bounds of the head-island faces in front of the ears, from 14.5 cm below the eyes to
/// 7.5 cm above them (decimetres, around the eyes' midpoint `eyes`).
fn face_rect(base: &BaseMesh, eyes: [f32; 3]) -> Option<[[f32; 2]; 2]> {
    let body = base.group("body")?;
    let [[iu0, iv0], [iu1, iv1]] = HEAD_ISLAND;
    let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
    for f in base.faces.iter().filter(|f| f.group == body) {
        let uv = |t: u32| base.uvs.get(t as usize).copied();
        let inside = f.corners.iter().all(|&(v, t)| {
            let p = base.positions[v as usize];
            let in_island =
                uv(t).is_some_and(|[u, w]| (iu0..=iu1).contains(&u) && (iv0..=iv1).contains(&w));
            in_island
                && p[1] > eyes[1] - 1.45
                && p[1] < eyes[1] + 0.75
                && (p[0] - eyes[0]).abs() < 0.75
                && p[2] > eyes[2] - 0.35
        });
        if !inside {
            continue;
        }
        for &(_, t) in &f.corners {
            let c = uv(t)?;
            for k in 0..2 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
    }
    (lo[0] < hi[0] && lo[1] < hi[1]).then(|| {
        [
            [
                (lo[0] - FACE_RECT_PAD).max(iu0),
                (lo[1] - FACE_RECT_PAD).max(iv0),
            ],
            [
                (hi[0] + FACE_RECT_PAD).min(iu1),
                (hi[1] + FACE_RECT_PAD).min(iv1),
            ],
        ]
    })
}

impl FaceUv {
    /// Finds the landmarks on the unshaped base mesh; `None` if it is not hm08-like.
    pub fn find(base: &BaseMesh) -> Option<FaceUv> {
        let eye = |g: &str| {
            let idx = base.vertices_of(g);
            (!idx.is_empty()).then(|| {
                let n = idx.len() as f32;
                idx.iter().fold([0.0f32; 3], |a, &i| {
                    let p = base.positions[i as usize];
                    [a[0] + p[0] / n, a[1] + p[1] / n, a[2] + p[2] / n]
                })
            })
        };
        let (l, r) = (eye("helper-l-eye")?, eye("helper-r-eye")?);
        let ey = 0.5 * (l[1] + r[1]);
        let half = 0.5 * (l[0] - r[0]).abs();
        let mid = |dy: [f32; 2]| front_most(base, [-0.05, 0.05], [ey + dy[0], ey + dy[1]]);
        let (_, nose_tip) = mid([-0.45, -0.2])?;
        let (_, upper_lip) = mid([-0.75, -0.55])?;
        let (_, chin) = mid([-1.3, -1.0])?;
        let (_, forehead) = mid([0.35, 0.6])?;
        let cheek = |x: f32| front_most(base, [x - 0.08, x + 0.08], [ey - 0.45, ey - 0.25]);
        let brow = |x: f32| front_most(base, [x - 0.08, x + 0.08], [ey + 0.12, ey + 0.22]);
        let (lc, rc) = (cheek(l[0])?.1, cheek(r[0])?.1);
        let (lb, rb) = (brow(l[0])?.1, brow(r[0])?.1);
        // 1.2-2.2 cm under the eye centre: found on the mesh, since the face's vertical axis
        // is not a UV axis in hm08's layout.
        let under = |x: f32| front_most(base, [x - 0.05, x + 0.05], [ey - 0.22, ey - 0.12]);
        let (lu, ru) = (under(l[0])?.1, under(r[0])?.1);
        // Eye distance: 2·half dm in space, the two brow UVs apart in the texture.
        let duv = ((lb[0] - rb[0]).powi(2) + (lb[1] - rb[1]).powi(2)).sqrt();
        let uv_per_cm = duv / (2.0 * half * 10.0);
        let face_rect = face_rect(base, [0.5 * (l[0] + r[0]), ey, 0.5 * (l[2] + r[2])])?;
        Some(FaceUv {
            cheeks: [lc, rc],
            nose_tip,
            chin,
            forehead,
            upper_lip,
            brows: [lb, rb],
            under_eyes: [lu, ru],
            uv_per_cm,
            face_rect,
        })
    }
}

/// Extra blood at the centre of a cheek, relative to the base skin: a person's skin tone is
/// set on the cheek (where ITA° is measured), so the base is derived with this gain.
pub const CHEEK_BLOOD: f32 = 1.2;

/// What varies a skin's look from person to person.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkinLook {
    pub base: Chromophores,
    /// 0..1 freckle density.
    pub freckles: f32,
    /// 0..1 beard-shadow strength (0 for women and the young).
    pub beard: f32,
    pub seed: u64,
}

/// The four textures of one skin region.
pub struct SkinTextures {
    pub albedo: Texture,
    pub normal: Texture,
    /// glTF metallic-roughness: G multiplies the preset's roughness, B the metalness (0).
    pub roughness: Texture,
    /// KHR_materials_specular: A multiplies the specular weight.
    pub specular: Texture,
}

fn spot(uv: [f32; 2], c: [f32; 2], radius: f32) -> f32 {
    let d2 = (uv[0] - c[0]).powi(2) + (uv[1] - c[1]).powi(2);
    let x = d2 / (radius * radius);
    // A rational bump instead of exp keeps texels identical across libm implementations.
    1.0 / (1.0 + x * x * x)
}

fn srgb8(linear: f64) -> u8 {
    let x = linear.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * libm::pow(x, 1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Per-texel chromophore multipliers and surface factors at OBJ UV `uv`.
struct Texel {
    melanin: f32,
    blood: f32,
    darken: f32,
    roughness: f32,
    specular: f32,
    height: f32,
}

fn texel(model: &MakeHuman, look: &SkinLook, uv: [f32; 2]) -> Texel {
    let f = &model.face_uv;
    let m = &model.masks;
    let lips = m.lips.sample(uv[0], uv[1], 0);
    let lids = m.eyelids.sample(uv[0], uv[1], 0);
    let ears = m.ears.sample(uv[0], uv[1], 0);
    let face = m.face.sample(uv[0], uv[1], 0);
    let cm = f.uv_per_cm;
    let cheeks = spot(uv, f.cheeks[0], 2.2 * cm).max(spot(uv, f.cheeks[1], 2.2 * cm));
    let nose = spot(uv, f.nose_tip, 1.3 * cm);
    let tzone = spot(uv, f.forehead, 3.0 * cm)
        .max(nose)
        .max(spot(uv, f.chin, 1.5 * cm));
    let under_eye =
        lids.max(spot(uv, f.under_eyes[0], 0.9 * cm))
            .max(spot(uv, f.under_eyes[1], 0.9 * cm));
    let s = look.seed;
    // Blotchiness on the scale of a centimetre, and pores at a third of a millimetre.
    let blotch = noise::fbm(uv[0] / cm, uv[1] / cm, s);
    let pores = noise::value(uv[0] / (0.035 * cm), uv[1] / (0.035 * cm), s ^ 0x5151);

    let mut melanin = (1.0 + 0.10 * blotch) * (1.0 + 0.35 * under_eye) * (1.0 - 0.35 * lips);
    let mut blood =
        (1.0 + 0.25 * blotch) * (1.0 + CHEEK_BLOOD * cheeks + 0.9 * nose + 0.8 * ears + 3.0 * lips);

    // Freckles: at most one per 3 mm cell, denser on the cheeks and nose.
    let cell = 0.3 * cm;
    let (cx, cy) = ((uv[0] / cell).floor() as i32, (uv[1] / cell).floor() as i32);
    let where_ = 0.25 + cheeks + nose;
    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (-1, 0), (0, -1)] {
        let (gx, gy) = (cx + dx, cy + dy);
        let p = noise::lattice(gx, gy, s ^ 0xF1EC);
        if p < look.freckles * 0.45 * where_ * face {
            let ox = (gx as f32 + noise::lattice(gx, gy, s ^ 0xA1)) * cell;
            let oy = (gy as f32 + noise::lattice(gx, gy, s ^ 0xB2)) * cell;
            let r = (0.05 + 0.07 * noise::lattice(gx, gy, s ^ 0xC3)) * cm;
            melanin *= 1.0 + 1.3 * spot(uv, [ox, oy], r);
        }
    }
    // Moles and red blemishes: rare, 2 cm cells.
    let big = 2.0 * cm;
    let (bx, by) = ((uv[0] / big).floor() as i32, (uv[1] / big).floor() as i32);
    let p = noise::lattice(bx, by, s ^ 0x30E);
    let ox = (bx as f32 + noise::lattice(bx, by, s ^ 0x31)) * big;
    let oy = (by as f32 + noise::lattice(bx, by, s ^ 0x32)) * big;
    if p < 0.05 {
        let r = (0.08 + 0.1 * noise::lattice(bx, by, s ^ 0x33)) * cm;
        melanin *= 1.0 + 5.0 * spot(uv, [ox, oy], r);
    } else if p < 0.09 {
        blood *= 1.0 + 2.0 * spot(uv, [ox, oy], 0.15 * cm);
    }
    // Stubble under the skin of the jaw, chin and upper lip.
    let beard_area = (spot(uv, f.chin, 2.8 * cm).max(spot(uv, f.upper_lip, 1.4 * cm))
        + 0.6 * cheeks * spot(uv, f.chin, 5.0 * cm))
    .min(1.0)
        * (1.0 - lips);
    let darken = 1.0 - 0.35 * look.beard * beard_area * (0.7 + 0.6 * pores);
    Texel {
        melanin,
        blood,
        darken,
        roughness: (1.0 - 0.22 * tzone - 0.2 * lips + 0.08 * cheeks).clamp(0.5, 1.0),
        specular: (0.82 + 0.18 * tzone.max(lips)).min(1.0),
        height: pores * face,
    }
}

/// The person's albedo lookup, built once and shared by all of their textures.
pub fn albedo_table(look: &SkinLook) -> AlbedoTable {
    AlbedoTable::new(look.base.eumelanin_ratio, look.base.oxygenation, 48, 32)
}

/// Renders the four textures of the UV rectangle `rect` (OBJ UVs, [min, max]) at
/// `width × height`, row 0 at the rect's top (max v); `table` is [`albedo_table`]`(look)`.
pub fn skin_textures(
    model: &MakeHuman,
    look: &SkinLook,
    table: &AlbedoTable,
    rect: [[f32; 2]; 2],
    width: u32,
    height: u32,
) -> SkinTextures {
    let n = (width * height) as usize;
    let mut albedo = vec![0u8; n * 4];
    let mut rough = vec![0u8; n * 4];
    let mut spec = vec![0u8; n * 4];
    let mut heights = vec![0f32; n];
    let [[u0, v0], [u1, v1]] = rect;
    for y in 0..height {
        let v = v1 - (y as f32 + 0.5) / height as f32 * (v1 - v0);
        for x in 0..width {
            let u = u0 + (x as f32 + 0.5) / width as f32 * (u1 - u0);
            let t = texel(model, look, [u, v]);
            let rgb = table.albedo(
                look.base.melanin * f64::from(t.melanin),
                look.base.haemoglobin * f64::from(t.blood),
            );
            let i = (y * width + x) as usize;
            for c in 0..3 {
                albedo[i * 4 + c] = srgb8(rgb[c] * f64::from(t.darken));
            }
            albedo[i * 4 + 3] = 255;
            rough[i * 4..i * 4 + 4].copy_from_slice(&[
                0,
                (t.roughness * 255.0 + 0.5) as u8,
                0,
                255,
            ]);
            spec[i * 4..i * 4 + 4].copy_from_slice(&[
                255,
                255,
                255,
                (t.specular * 255.0 + 0.5) as u8,
            ]);
            heights[i] = t.height;
        }
    }
    // Pores as dimples: the normal of the height field, one texel per finite difference.
    let strength = 0.6;
    let mut normal = vec![0u8; n * 4];
    for y in 0..height as usize {
        for x in 0..width as usize {
            let at = |x: usize, y: usize| heights[y * width as usize + x];
            let xl = x.saturating_sub(1);
            let xr = (x + 1).min(width as usize - 1);
            let yu = y.saturating_sub(1);
            let yd = (y + 1).min(height as usize - 1);
            let dx = (at(xr, y) - at(xl, y)) * strength;
            // Rows run down the texture while v runs up.
            let dy = (at(x, yu) - at(x, yd)) * strength;
            let len = (dx * dx + dy * dy + 1.0).sqrt();
            let nrm = [-dx / len, -dy / len, 1.0 / len];
            let i = (y * width as usize + x) * 4;
            for c in 0..3 {
                normal[i + c] = ((nrm[c] * 0.5 + 0.5) * 255.0 + 0.5) as u8;
            }
            normal[i + 3] = 255;
        }
    }
    let tex = |rgba8| Texture {
        width,
        height,
        rgba8,
    };
    SkinTextures {
        albedo: tex(albedo),
        normal: tex(normal),
        roughness: tex(rough),
        specular: tex(spec),
    }
}
