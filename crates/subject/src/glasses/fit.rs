//! Glasses: the fit of a glasses model to a head, temples bent at their hinges (see the parent module).

#[allow(unused_imports)]
use super::*;

// ---------------------------------------------------------------------------------------------
// Fit
// ---------------------------------------------------------------------------------------------

/// Scale limits: beyond them a model is the wrong size for a face, not a fit problem.
const MIN_SCALE: f32 = 0.8;
const MAX_SCALE: f32 = 1.25;
/// Eyeball centre to lens plane: ~11 mm to the cornea apex plus a 12–14 mm vertex distance.
const EYE_TO_LENS: f32 = 0.024;
/// The lens plane never comes closer than this in front of the nose bridge.
const NOSE_CLEARANCE: f32 = 0.003;
const MAX_PITCH_DEGREES: f32 = 15.0;

/// The model→head transform of a glasses model: rotation taking `forward`→+Z and `up`→+Y,
/// uniform scale so the lens centres are as far apart as the eyes (clamped to 0.8–1.25, so
/// over-size frames stay over-size rather than shrinking to toys), translation putting the lens
/// centres' midpoint in front of the eyes' midpoint at `EYE_TO_LENS` but at least
/// `NOSE_CLEARANCE` in front of the nose bridge, then a pitch about the lens midpoint (±15° at
/// most) that brings the temples' ear rest points to the height of the ear landmarks.
///
/// The scale follows the eye distance rather than the ear span because the lenses must sit in
/// front of the pupils; temples of the wrong width or length are bent by [`place_glasses`].
pub fn fit_glasses(anchors: &GlassesAnchors, lm: &Landmarks) -> Mat4 {
    let forward = anchors.forward.normalize_or(Vec3::Z);
    let up = (anchors.up - forward * anchors.up.dot(forward)).normalize_or(Vec3::Y);
    let left = up.cross(forward);
    let rotation = Mat3::from_cols(left, up, forward).transpose();
    let mid = anchors.lens_centre();
    let lens_distance = anchors.lens_left.distance(anchors.lens_right);
    let scale = if lens_distance > 0.0 {
        (lm.eye_distance() / lens_distance).clamp(MIN_SCALE, MAX_SCALE)
    } else {
        1.0
    };
    let eyes = lm.eye_centre();
    let target = Vec3::new(
        eyes.x,
        eyes.y,
        (eyes.z + EYE_TO_LENS).max(lm.nose_bridge.z + NOSE_CLEARANCE),
    );

    // Elevation of the ear rest points seen from the lens midpoint, before and after.
    let ears = rotation * ((anchors.ear_left + anchors.ear_right) * 0.5 - mid) * scale;
    let reach = Vec2::new(ears.y, ears.z).length();
    let ear_height = 0.5 * (lm.ear_left.y + lm.ear_right.y) - target.y;
    let pitch = if ears.z < 0.0 && reach > 0.0 {
        let now = ears.y.atan2(-ears.z);
        let wanted = (ear_height / reach).clamp(-1.0, 1.0).asin();
        let limit = MAX_PITCH_DEGREES.to_radians();
        (wanted - now).clamp(-limit, limit)
    } else {
        0.0
    };
    Mat4::from_translation(target)
        * Mat4::from_rotation_x(pitch)
        * Mat4::from_scale(Vec3::splat(scale))
        * Mat4::from_mat3(rotation)
        * Mat4::from_translation(-mid)
}

/// Outward clearance between an ear landmark (the outermost skin there) and the temple's centre
/// line.
const EAR_CLEARANCE: f32 = 0.003;
/// The temples bend from this fraction of the ear rest point's depth behind the lens plane:
/// behind the hinges, in front of everything that rests on the head.
const HINGE_FRACTION: f32 = 0.2;
/// Gap kept between the frame front and the skin when the skin pushes the frame out.
const SKIN_CLEARANCE: f32 = 0.0005;
/// Most the skin may push the frame forward; beyond it the frame stays where it touches.
const MAX_PUSH: f32 = 0.015;
/// Pantoscopic tilts (top of the frame forward, degrees) tried when the brows or cheeks touch.
const TILTS: [f32; 5] = [0.0, 3.0, 6.0, 9.0, 12.0];
/// A degree of tilt is worth this much push: tilt is only taken where it saves distance.
const PUSH_PER_DEGREE: f32 = 0.0003;

/// How far one temple's ear rest point is moved, in the model frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TempleBend {
    /// Away from the midline (negative: inwards).
    pub outward: f32,
    pub up: f32,
    /// Further behind the lens plane (a longer temple; negative: shorter).
    pub back: f32,
}

/// The bends that bring each temple's ear rest point to its ear landmark (plus an outward
/// clearance) once `fit` (from [`fit_glasses`], possibly adjusted) has placed the front. Each is
/// clamped relative to the temple's hinge-to-ear length: outward −15 %…+60 %, up ±25 %, back
/// −30 %…+60 %.
pub fn temple_bends(anchors: &GlassesAnchors, fit: Mat4, lm: &Landmarks) -> [TempleBend; 2] {
    let inverse = fit.inverse();
    let mid = anchors.lens_centre();
    let left = anchors.left();
    let midline = lm.eye_centre().x;
    let bend = |anchor: Vec3, ear: Vec3, side: f32| {
        let outward_x = if ear.x >= midline { 1.0 } else { -1.0 };
        let target = ear + Vec3::X * (outward_x * EAR_CLEARANCE);
        let delta = inverse.transform_point3(target) - anchor;
        let depth = (mid - anchor).dot(anchors.forward);
        let length = (1.0 - HINGE_FRACTION) * depth.max(0.0);
        TempleBend {
            outward: (delta.dot(left) * side).clamp(-0.15 * length, 0.6 * length),
            up: delta.dot(anchors.up).clamp(-0.25 * length, 0.25 * length),
            back: (-delta.dot(anchors.forward)).clamp(-0.3 * length, 0.6 * length),
        }
    };
    [
        bend(anchors.ear_left, lm.ear_left, 1.0),
        bend(anchors.ear_right, lm.ear_right, -1.0),
    ]
}

/// A glasses model fitted to one head.
///
/// Starts from [`fit_glasses`]. Where the frame front (everything in front of the temples'
/// hinges) would then cut into `skin` — prominent brows, a high nose — the frame is tilted
/// (pantoscopic tilt about the lens centres, up to 12°, only while |pitch| stays ≤ 15°) and
/// pushed forward along +Z until it clears the skin, choosing the tilt that needs the least
/// push; the push is capped at 15 mm. Pass an empty [`HeadSurface`] to skip this. Then each
/// temple is bent by [`temple_bends`]: every point behind the hinge moves by the bend times
/// its fraction of the way from the hinge to the ear rest point (constant beyond), so the ear
/// rest point lands on its ear as an optician would bend it.
///
/// Each instance's mesh is copied into the model frame (instance transforms baked, so an
/// instanced mesh becomes one mesh per instance; morph targets dropped) and every instance
/// gets the final model→head transform.
pub fn place_glasses(
    scene: &Scene,
    lm: &Landmarks,
    skin: &HeadSurface,
) -> Result<Scene, SubjectError> {
    let anchors = glasses_anchors(scene)?;
    let mid = anchors.lens_centre();
    let (left, up, forward) = (anchors.left(), anchors.up, anchors.forward);
    let ear_depths = [anchors.ear_left, anchors.ear_right].map(|e| (mid - e).dot(forward).max(0.0));

    let mut meshes: Vec<Mesh> = Vec::with_capacity(scene.instances.len());
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        meshes.push(baked(mesh, inst.transform));
    }

    let mut fit = fit_glasses(&anchors, lm);
    if !skin.triangles.is_empty() {
        let hinge = HINGE_FRACTION * ear_depths[0].min(ear_depths[1]);
        let front: Vec<Vec3> = meshes
            .iter()
            .flat_map(|m| m.positions.iter().map(|p| Vec3::from(*p)))
            .filter(|p| (mid - *p).dot(forward) < hinge)
            .collect();
        let index = SkinIndex::new(skin)?;
        let facing = fit.transform_vector3(forward).normalize_or(Vec3::Z);
        fit = clear_of_skin(fit, fit.transform_point3(mid), facing, &front, &index);
    }

    let bends = temple_bends(&anchors, fit, lm);
    let deformations: Vec<TempleDeformation> = [
        (ear_depths[0], bends[0], 1.0),
        (ear_depths[1], bends[1], -1.0),
    ]
    .iter()
    .map(|&(depth, bend, side)| {
        let start = HINGE_FRACTION * depth;
        TempleDeformation {
            start,
            length: (depth - start).max(f32::MIN_POSITIVE),
            delta: left * (side * bend.outward) + up * bend.up - forward * bend.back,
        }
    })
    .collect();
    let mut out = Scene {
        materials: scene.materials.clone(),
        textures: scene.textures.clone(),
        ..Scene::default()
    };
    for mut mesh in meshes {
        for ((p, n), t) in mesh
            .positions
            .iter_mut()
            .zip(mesh.normals.iter_mut())
            .zip(mesh.tangents.iter_mut())
        {
            let at = Vec3::from(*p);
            let side = usize::from((at - mid).dot(left) < 0.0);
            let behind = (mid - at).dot(forward);
            let tangent = Vec3::new(t[0], t[1], t[2]);
            let (at, normal, tangent) =
                deformations[side].apply(at, Vec3::from(*n), tangent, behind, forward);
            *p = at.to_array();
            *n = normal.to_array();
            let tangent = tangent.normalize_or_zero();
            *t = [tangent.x, tangent.y, tangent.z, t[3]];
        }
        out.meshes.push(mesh);
        out.instances.push(Instance {
            mesh: (out.meshes.len() - 1) as u32,
            transform: fit,
        });
    }
    Ok(out)
}

/// `mesh` with `transform` applied to its vertices, normals and tangents.
fn baked(mesh: &Mesh, transform: Mat4) -> Mesh {
    let normal_matrix = Mat3::from_mat4(transform).inverse().transpose();
    let mut out = mesh.clone();
    out.morph_targets.clear();
    for p in &mut out.positions {
        *p = transform.transform_point3(Vec3::from(*p)).to_array();
    }
    for n in &mut out.normals {
        let m = (normal_matrix * Vec3::from(*n)).normalize_or_zero();
        if m != Vec3::ZERO {
            *n = m.to_array();
        }
    }
    for t in &mut out.tangents {
        let m = transform.transform_vector3(Vec3::new(t[0], t[1], t[2]));
        let m = m.normalize_or_zero();
        *t = [m.x, m.y, m.z, t[3]];
    }
    out
}

/// `fit` tilted about `pivot` (head frame) and pushed along +Z so that no point of `front`
/// (model frame) is inside the skin: of the tilts in [`TILTS`] the one needing the least push,
/// a degree of tilt counting as [`PUSH_PER_DEGREE`] of push.
fn clear_of_skin(fit: Mat4, pivot: Vec3, facing: Vec3, front: &[Vec3], skin: &SkinIndex) -> Mat4 {
    // Rx(θ) turns +Z to (0, −sin θ, cos θ): the fit's own pitch, which the tilt adds to.
    let pitch = (-facing.y).atan2(facing.z).to_degrees();
    let mut best: Option<(f32, Mat4)> = None;
    for tilt in TILTS {
        if tilt > 0.0 && pitch + tilt > MAX_PITCH_DEGREES {
            break;
        }
        let tilted = Mat4::from_translation(pivot)
            * Mat4::from_rotation_x(tilt.to_radians())
            * Mat4::from_translation(-pivot)
            * fit;
        let points: Vec<Vec3> = front.iter().map(|p| tilted.transform_point3(*p)).collect();
        let push = skin.push_out(&points);
        let cost = push + tilt * PUSH_PER_DEGREE;
        if best.is_none_or(|(c, _)| cost < c) {
            best = Some((cost, Mat4::from_translation(Vec3::Z * push) * tilted));
        }
        if push == 0.0 {
            break;
        }
    }
    best.map_or(fit, |(_, m)| m)
}

/// Skin vertices with their normals, bucketed in a uniform grid.
struct SkinIndex<'a> {
    skin: &'a HeadSurface,
    cells: std::collections::HashMap<[i32; 3], Vec<u32>>,
}

/// Grid cell size of [`SkinIndex`]: a little above the vertex spacing of the heads' faces.
const SKIN_CELL: f32 = 0.006;

fn skin_cell(p: Vec3) -> [i32; 3] {
    let c = (p / SKIN_CELL).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

impl<'a> SkinIndex<'a> {
    fn new(skin: &'a HeadSurface) -> Result<SkinIndex<'a>, SubjectError> {
        let mut used = vec![false; skin.positions.len()];
        for t in &skin.triangles {
            for &i in t {
                match used.get_mut(i as usize) {
                    Some(u) if (i as usize) < skin.normals.len() => *u = true,
                    _ => {
                        return Err(SubjectError::Asset {
                            asset: "head surface".to_string(),
                            reason: format!(
                                "a skin triangle refers to vertex {i}, but there are {} \
                                 positions and {} normals",
                                skin.positions.len(),
                                skin.normals.len()
                            ),
                        })
                    }
                }
            }
        }
        let mut cells: std::collections::HashMap<[i32; 3], Vec<u32>> = Default::default();
        for (i, p) in skin.positions.iter().enumerate() {
            if used[i] {
                cells.entry(skin_cell(*p)).or_default().push(i as u32);
            }
        }
        Ok(SkinIndex { skin, cells })
    }

    /// How far inside the skin `p` is (negative: outside), judged from the nearest skin vertex
    /// and its normal, with that normal; `None` when no skin is within a cell.
    fn depth(&self, p: Vec3) -> Option<(f32, Vec3)> {
        let c = skin_cell(p);
        let mut best: Option<(f32, u32)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(ids) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for &i in ids {
                        let d = self.skin.positions[i as usize].distance_squared(p);
                        if best.is_none_or(|(bd, _)| d < bd) {
                            best = Some((d, i));
                        }
                    }
                }
            }
        }
        let (_, i) = best?;
        let n = self.skin.normals[i as usize];
        Some((-(p - self.skin.positions[i as usize]).dot(n), n))
    }

    /// The push along +Z after which every point is at least [`SKIN_CLEARANCE`] outside the
    /// skin (refined a few times, as pushed points meet other skin), at most [`MAX_PUSH`].
    fn push_out(&self, points: &[Vec3]) -> f32 {
        let mut push = 0.0f32;
        for _ in 0..4 {
            let step = points
                .iter()
                .filter_map(|p| self.depth(*p + Vec3::Z * push))
                .map(|(depth, n)| (depth + SKIN_CLEARANCE) / n.z.max(0.25))
                .fold(0.0f32, f32::max);
            push = (push + step).min(MAX_PUSH);
            if step < 1e-5 || push >= MAX_PUSH {
                break;
            }
        }
        push
    }
}

/// p' = p + r(depth)·delta with r rising linearly from 0 at `start` to 1 at `start + length`.
struct TempleDeformation {
    start: f32,
    length: f32,
    delta: Vec3,
}

impl TempleDeformation {
    fn apply(&self, p: Vec3, n: Vec3, t: Vec3, behind: f32, forward: Vec3) -> (Vec3, Vec3, Vec3) {
        let r = ((behind - self.start) / self.length).clamp(0.0, 1.0);
        let moved = p + self.delta * r;
        if r <= 0.0 || r >= 1.0 {
            return (moved, n, t);
        }
        // Jacobian I + delta gᵀ with g = ∇r = −forward/length; normals take its inverse
        // transpose (Sherman–Morrison), tangents the Jacobian itself.
        let g = -forward / self.length;
        let denominator = 1.0 + self.delta.dot(g);
        let normal = if denominator > 0.0 {
            (n - g * (self.delta.dot(n) / denominator)).normalize_or(n)
        } else {
            n
        };
        (moved, normal, t + self.delta * g.dot(t))
    }
}
