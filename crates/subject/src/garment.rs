//! Putting a fitted garment on a head it was not fitted to, and hiding the body under it.
//!
//! The MakeHuman garments were fitted to one body each (catalog tag `fitted_to`). Other heads
//! have their necks elsewhere, so the garment is moved by the difference of the two necks'
//! centres and scaled by the ratio of their widths. Skin the garment covers is then removed
//! rather than pushed in: body meshes poke through cloth at the shoulders otherwise, and the
//! covered skin is never seen (a cloth pipeline deletes hidden body parts the same way).

use glam::{Mat4, Vec3};

use crate::landmarks::{HeadSurface, Landmarks};

/// The neck where a collar sits: `centre` is on the back of the neck, on the midline, 2 cm
/// above the shoulder line (chin and jaw make the front useless as a reference: on some heads
/// they reach down to the collar).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neck {
    pub centre: Vec3,
    pub half_width: f32,
}

impl Neck {
    /// A point inside the neck, for axes that must run through the body.
    pub fn inside(&self) -> Vec3 {
        self.centre + Vec3::new(0.0, 0.0, self.half_width)
    }
}

/// Where the shoulders are searched, below the eye line.
const SHOULDER_SEARCH_M: [f32; 2] = [0.06, 0.25];
/// The shoulder line is where the body first gets wider than this (half-width) going down:
/// wider than any neck, narrower than any pair of shoulders.
const SHOULDER_START_HALF_WIDTH_M: f32 = 0.09;
/// Shoulders are wider than the neck above them by at least this factor (a neck's half-width
/// is 4.5-7.5 cm, the shoulders' 15-20 cm).
const SHOULDER_OVER_NECK: f32 = 1.25;
/// The collar reference is this far above the shoulder line.
const NECK_ABOVE_SHOULDERS_M: f32 = 0.02;
/// Shoulders are measured this far below the shoulder line.
const SHOULDER_BELOW_LINE_M: f32 = 0.05;

/// Extent of the skin's cross-section at height `y`: (min, max, how many edges cross it).
/// The plane through the triangles, not the vertices near it: a neck's vertex rings are
/// 1-2 cm apart, so a thin slab of vertices can miss the back of the neck on one body and not
/// on the next (a collar was placed 4.5 cm forward that way, cutting into the throat).
fn slab(surface: &HeadSurface, y: f32) -> (Vec3, Vec3, usize) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    let mut n = 0;
    for t in &surface.triangles {
        for k in 0..3 {
            let (Some(&a), Some(&b)) = (
                surface.positions.get(t[k] as usize),
                surface.positions.get(t[(k + 1) % 3] as usize),
            ) else {
                continue;
            };
            if (a.y <= y) == (b.y <= y) {
                continue;
            }
            let p = a + (b - a) * ((y - a.y) / (b.y - a.y));
            lo = lo.min(p);
            hi = hi.max(p);
            n += 1;
        }
    }
    (lo, hi, n)
}

/// The height where the neck meets the shoulders, `None` when the mesh stops above them:
/// going down, the first slab wider than [`SHOULDER_START_HALF_WIDTH_M`] and than
/// [`SHOULDER_OVER_NECK`] × the narrowest slab above it. The second condition skips a broad
/// jaw or full cheeks at the top of the search (a heavy face can be 19 cm wide 6 cm under the
/// eyes; taking that for the shoulders put the collar at the mouth).
pub fn shoulder_line(surface: &HeadSurface, lm: &Landmarks) -> Option<f32> {
    let eye_y = lm.eye_centre().y;
    let steps = ((SHOULDER_SEARCH_M[1] - SHOULDER_SEARCH_M[0]) / 0.005) as usize;
    let mut narrowest = f32::INFINITY;
    (0..=steps)
        .map(|k| eye_y - SHOULDER_SEARCH_M[0] - k as f32 * 0.005)
        .find(|&y| {
            let (lo, hi, n) = slab(surface, y);
            if n < 8 {
                return false;
            }
            let half_width = (hi.x - lo.x) * 0.5;
            let found = half_width > SHOULDER_START_HALF_WIDTH_M
                && half_width > SHOULDER_OVER_NECK * narrowest;
            narrowest = narrowest.min(half_width);
            found
        })
}

/// The neck 2 cm above the shoulder line; `None` when there is no shoulder line.
pub fn measure_neck(surface: &HeadSurface, lm: &Landmarks) -> Option<Neck> {
    let y = shoulder_line(surface, lm)? + NECK_ABOVE_SHOULDERS_M;
    let (lo, hi, n) = slab(surface, y);
    (n >= 8).then(|| Neck {
        centre: Vec3::new((lo.x + hi.x) * 0.5, y, lo.z),
        half_width: (hi.x - lo.x) * 0.5,
    })
}

/// Half-width of the skin `SHOULDER_BELOW_LINE_M` under the shoulder line, `None` without
/// skin there.
pub fn measure_shoulders(surface: &HeadSurface, neck: &Neck) -> Option<f32> {
    let y = neck.centre.y - NECK_ABOVE_SHOULDERS_M - SHOULDER_BELOW_LINE_M;
    let (lo, hi, n) = slab(surface, y);
    (n >= 8).then(|| (hi.x - neck.centre.x).max(neck.centre.x - lo.x))
}

/// A body's fit measurements: neck and shoulder half-width.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Body {
    pub neck: Neck,
    /// `None` when the mesh ends above the shoulders; the neck's scale is used then.
    pub shoulder_half_width: Option<f32>,
}

impl Body {
    pub fn measure(surface: &HeadSurface, lm: &Landmarks) -> Option<Body> {
        let neck = measure_neck(surface, lm)?;
        Some(Body {
            neck,
            shoulder_half_width: measure_shoulders(surface, &neck),
        })
    }
}

/// Garment (fitted to body `fitted`) → body `target`: a warp that moves the neck centres
/// together and scales horizontally by the neck-width ratio at the collar, blending to the
/// shoulder-width ratio 7 cm below it (a bulky neck on narrow
/// shoulders needs a wider collar, not a wider coat).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GarmentFit {
    from: Vec3,
    to: Vec3,
    axis: Vec3,
    neck_scale: f32,
    shoulder_scale: f32,
}

impl GarmentFit {
    pub fn new(fitted: &Body, target: &Body) -> GarmentFit {
        let ratio = |a: f32, b: f32| if a > 1e-4 { b / a } else { 1.0 };
        let neck_scale = ratio(fitted.neck.half_width, target.neck.half_width).clamp(0.8, 1.6);
        let shoulder_scale = match (fitted.shoulder_half_width, target.shoulder_half_width) {
            (Some(a), Some(b)) => ratio(a, b).clamp(0.8, 1.3),
            _ => neck_scale.min(1.3),
        };
        GarmentFit {
            from: fitted.neck.centre,
            to: target.neck.centre,
            axis: target.neck.inside(),
            neck_scale,
            shoulder_scale,
        }
    }

    /// For a body whose neck could not be measured: the garment goes where it sits on the body
    /// it was made for relative to the eyes, unscaled.
    pub fn by_eyes(fitted: &Body, fitted_eyes: Vec3, target_eyes: Vec3) -> GarmentFit {
        GarmentFit {
            from: fitted.neck.centre,
            to: fitted.neck.centre - fitted_eyes + target_eyes,
            axis: fitted.neck.inside() - fitted_eyes + target_eyes,
            neck_scale: 1.0,
            shoulder_scale: 1.0,
        }
    }

    /// A vertical axis through the target's neck (for [`CoverMap`]).
    pub fn body_axis(&self) -> Vec3 {
        self.axis
    }

    /// Horizontal scale at height `y` (garment space).
    pub fn scale_at(&self, y: f32) -> f32 {
        let t =
            ((self.from.y - y) / (NECK_ABOVE_SHOULDERS_M + SHOULDER_BELOW_LINE_M)).clamp(0.0, 1.0);
        self.neck_scale + (self.shoulder_scale - self.neck_scale) * t
    }

    pub fn apply(&self, p: Vec3) -> Vec3 {
        let s = self.scale_at(p.y);
        let d = p - self.from;
        self.to + Vec3::new(d.x * s, d.y, d.z * s)
    }

    /// Warps every instance of `scene` in place (positions baked into world space, instance
    /// transforms set to identity, normals recomputed).
    pub fn warp_scene(&self, scene: &mut lightfarm_render::scene::Scene) {
        let instances = std::mem::take(&mut scene.instances);
        let mut meshes = Vec::with_capacity(instances.len());
        for inst in &instances {
            let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
                continue;
            };
            let mut mesh = mesh.clone();
            for p in mesh.positions.iter_mut() {
                *p = self
                    .apply(inst.transform.transform_point3(Vec3::from(*p)))
                    .to_array();
            }
            mesh.morph_targets.clear();
            mesh.recompute_normals();
            meshes.push(mesh);
        }
        scene.instances = (0..meshes.len() as u32)
            .map(|mesh| lightfarm_render::scene::Instance {
                mesh,
                transform: Mat4::IDENTITY,
            })
            .collect();
        scene.meshes = meshes;
    }
}

/// Where a garment is, as seen from the body axis: for each (angle, height) bin the garment
/// covers, the largest radius of cloth there.
pub struct CoverMap {
    axis: Vec3,
    y0: f32,
    radius: Vec<f32>,
}

const ANGLE_BINS: usize = 72;
const HEIGHT_BIN_M: f32 = 0.01;

impl CoverMap {
    /// Rasterises the garment's triangles (world space) around a vertical axis through `axis`.
    pub fn new(axis: Vec3, triangles: &[[Vec3; 3]]) -> CoverMap {
        let y0 = triangles
            .iter()
            .flatten()
            .map(|p| p.y)
            .fold(f32::INFINITY, f32::min);
        let y1 = triangles
            .iter()
            .flatten()
            .map(|p| p.y)
            .fold(f32::NEG_INFINITY, f32::max);
        let rows = if y1 >= y0 {
            ((y1 - y0) / HEIGHT_BIN_M) as usize + 1
        } else {
            0
        };
        let mut map = CoverMap {
            axis,
            y0,
            radius: vec![0.0; rows * ANGLE_BINS],
        };
        for t in triangles {
            // Enough samples that no bin inside a triangle is skipped: spacing ≤ half a bin.
            let extent = (t[1] - t[0]).length().max((t[2] - t[0]).length());
            let n = ((extent / (HEIGHT_BIN_M * 0.5)).ceil() as usize).clamp(1, 64);
            for i in 0..=n {
                for j in 0..=(n - i) {
                    let (a, b) = (i as f32 / n as f32, j as f32 / n as f32);
                    let p = t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b;
                    if let Some(k) = map.bin(p) {
                        let r = map.radial(p);
                        if r > map.radius[k] {
                            map.radius[k] = r;
                        }
                    }
                }
            }
        }
        map
    }

    fn radial(&self, p: Vec3) -> f32 {
        let d = p - self.axis;
        (d.x * d.x + d.z * d.z).sqrt()
    }

    fn bin(&self, p: Vec3) -> Option<usize> {
        let row = ((p.y - self.y0) / HEIGHT_BIN_M).floor();
        if row.is_nan() || row < 0.0 {
            return None;
        }
        let row = row as usize;
        let d = p - self.axis;
        let angle = d.z.atan2(d.x) + std::f32::consts::PI;
        let col = ((angle / std::f32::consts::TAU) * ANGLE_BINS as f32) as usize % ANGLE_BINS;
        let k = row * ANGLE_BINS + col;
        (k < self.radius.len()).then_some(k)
    }

    /// The largest radius of cloth at `p`'s angle and height, if there is cloth there.
    pub fn cloth_radius(&self, p: Vec3) -> Option<f32> {
        self.bin(p)
            .and_then(|k| self.radius.get(k))
            .copied()
            .filter(|&r| r > 0.0)
    }

    /// Whether cloth lies at `p`'s angle and height at least as far out as `p` minus `slack`
    /// (so skin just outside a tight garment, which would poke through, counts as covered),
    /// and the bin above has cloth too: the top row of a collar covers only part of its bin,
    /// and skin removed there shows as dark gaps above the cloth's edge.
    pub fn covers(&self, p: Vec3, slack: f32) -> bool {
        self.cloth_radius(p)
            .is_some_and(|r| r + slack >= self.radial(p))
            && self.cloth_radius(p + Vec3::Y * HEIGHT_BIN_M).is_some()
    }

    /// The largest radius in `p`'s bin and the bins beside it (the angle neighbours), so a
    /// surface pushed out by it clears the whole bin. Below the map's lowest row the lowest
    /// row stands in: a body cut off there (a bust) continues at least that wide, and cloth
    /// below the cut that kept its fitted body's narrower waist would pull the cloth just
    /// above it through the skin (identity 512 of `lightfarm people check`).
    fn radius_near(&self, p: Vec3) -> Option<f32> {
        let p = Vec3::new(p.x, p.y.max(self.y0), p.z);
        let k = self.bin(p)?;
        let row = k / ANGLE_BINS;
        let col = k % ANGLE_BINS;
        let r = [ANGLE_BINS - 1, 0, 1]
            .iter()
            .filter_map(|d| self.radius.get(row * ANGLE_BINS + (col + d) % ANGLE_BINS))
            .fold(0.0f32, |a, &b| a.max(b));
        (r > 0.0).then_some(r)
    }

    /// `p` (cloth) moved away from the body axis to `gap` outside this map's surface (skin),
    /// if it lies inside that.
    pub fn push_outside(&self, p: Vec3, gap: f32) -> Option<Vec3> {
        let r = self.radius_near(p)? + gap;
        let len = self.radial(p);
        if len >= r || len < 1e-4 {
            return None;
        }
        let d = p - self.axis;
        let k = r / len;
        Some(Vec3::new(self.axis.x + d.x * k, p.y, self.axis.z + d.z * k))
    }

    /// `p` moved towards the body axis to `gap` inside the cloth at its angle and height, if
    /// it lies outside that.
    pub fn pull_inside(&self, p: Vec3, gap: f32) -> Option<Vec3> {
        let r = self.cloth_radius(p)? - gap;
        let len = self.radial(p);
        if len <= r || r <= 0.0 {
            return None;
        }
        let d = p - self.axis;
        let k = r / len;
        Some(Vec3::new(self.axis.x + d.x * k, p.y, self.axis.z + d.z * k))
    }

    /// How far `p` lies outside the cloth at its angle and height (negative inside), if there
    /// is cloth there.
    pub fn outside_by(&self, p: Vec3) -> Option<f32> {
        self.cloth_radius(p).map(|r| self.radial(p) - r)
    }

    /// Whether skin at `p` would show through the cloth: cloth at its angle and height, and
    /// at the height above, lies more than `tolerance` inside it.
    pub fn pokes_through(&self, p: Vec3, tolerance: f32) -> bool {
        self.cloth_radius(p + Vec3::Y * HEIGHT_BIN_M).is_some()
            && self
                .cloth_radius(p)
                .is_some_and(|r| self.radial(p) > r + tolerance)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A body as rings of 16 points every 5 mm from 6 cm to 25 cm under the eyes, with the
    /// half-width `width(depth below the eyes)`.
    fn body(width: impl Fn(f32) -> f32) -> (HeadSurface, Landmarks) {
        body_rings(width, 0.005)
    }

    /// The same with rings `step` apart, joined by triangles.
    fn body_rings(width: impl Fn(f32) -> f32, step: f32) -> (HeadSurface, Landmarks) {
        let mut positions = Vec::new();
        let rings = (0.19 / step).round() as u32;
        for k in 0..=rings {
            let depth = 0.06 + k as f32 * step;
            let w = width(depth);
            for a in 0..16 {
                let t = a as f32 / 16.0 * std::f32::consts::TAU;
                positions.push(Vec3::new(w * t.cos(), -depth, 0.06 * t.sin()));
            }
        }
        let mut triangles = Vec::new();
        for k in 0..rings {
            for a in 0..16 {
                let (i, j) = (k * 16 + a, k * 16 + (a + 1) % 16);
                triangles.push([i, j, i + 16]);
                triangles.push([j, j + 16, i + 16]);
            }
        }
        let surface = HeadSurface {
            normals: vec![Vec3::Z; positions.len()],
            positions,
            triangles,
        };
        let eye = Vec3::new(0.0, 0.0, 0.08);
        let lm = Landmarks {
            eye_left: eye + Vec3::X * 0.03,
            eye_right: eye - Vec3::X * 0.03,
            ear_left: Vec3::X * 0.07,
            ear_right: -Vec3::X * 0.07,
            nose_bridge: eye + Vec3::Z * 0.02,
            crown: Vec3::Y * 0.12,
        };
        (surface, lm)
    }

    /// Shoulders start 15 cm under the eyes; above them a 6 cm neck, and for the second body a
    /// jaw 9.3 cm wide at the top of the search (identity 622 of `lightfarm people check`,
    /// whose collar the old rule put at the mouth).
    #[test]
    fn a_broad_jaw_is_not_the_shoulders() {
        let neck_then_shoulders = |d: f32| if d < 0.15 { 0.06 } else { 0.16 };
        let with_jaw = |d: f32| {
            if d < 0.07 {
                0.093
            } else {
                neck_then_shoulders(d)
            }
        };
        for (name, (surface, lm)) in [
            ("plain", body(neck_then_shoulders)),
            ("broad jaw", body(with_jaw)),
        ] {
            let y = shoulder_line(&surface, &lm).expect("a shoulder line");
            assert!(
                (-y - 0.15).abs() < 0.006,
                "{name}: shoulder line {:.3} m under the eyes, not 0.15",
                -y
            );
        }
    }

    /// Vertex rings 1.5 cm apart (a coarse body mesh's neck): the neck is still measured at
    /// its back and its full width, wherever the rings fall.
    #[test]
    fn the_neck_is_measured_between_sparse_vertex_rings() {
        let neck_then_shoulders = |d: f32| if d < 0.15 { 0.06 } else { 0.16 };
        let (surface, lm) = body_rings(neck_then_shoulders, 0.015);
        let neck = measure_neck(&surface, &lm).expect("a neck");
        // The back of a 16-gon ring of radius 6 cm: -0.06 at a vertex, -0.0588 mid-edge.
        assert!(
            neck.centre.z < -0.058,
            "the neck's back at z = {} m, not -0.06",
            neck.centre.z
        );
        assert!(
            (neck.half_width - 0.06).abs() < 0.003,
            "neck half-width {} m, not 0.06",
            neck.half_width
        );
    }
}
