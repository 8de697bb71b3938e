//! The scalp: where hair may grow relative to the landmarks ([`HeadFrame`]), the skin the
//! strands collide with ([`Skin`], [`LocalSkin`]) and the roots sampled on it.

use glam::Vec3;

use crate::landmarks::{closest_on_triangle, HeadSurface, Landmarks};

use super::grid::PointGrid;
use super::rng::Rng;
use super::{PROBE_RANGE, REF_CROWN_ABOVE_EYES, ROOT_LIFT};

/// Where strands may and may not go, relative to the landmarks.
pub(super) struct HeadFrame {
    pub(super) mid_x: f32,
    pub(super) eye_y: f32,
    pub(super) eye_z: f32,
    /// Foremost ear z: the face keep-out starts there.
    ear_front_z: f32,
    pub(super) ear_mid_z: f32,
    pub(super) ear_y: f32,
    ears: [Vec3; 2],
    pub(super) crown: Vec3,
    pub(super) k: f32,
    face_half_width: f32,
    face_bottom: f32,
    face_top: f32,
}

/// Hairline height above the eye line (metres at scale 1) against azimuth (degrees); see the
/// module documentation.
const HAIRLINE: [(f32, f32); 15] = [
    (0.0, 0.060),
    (25.0, 0.058),
    (32.0, 0.054),
    (40.0, 0.048),
    (48.0, 0.040),
    (54.0, 0.030),
    (58.0, 0.018),
    (62.0, 0.000),
    (66.0, -0.015),
    (72.0, -0.022),
    (80.0, -0.030),
    (90.0, -0.040),
    (110.0, -0.055),
    (135.0, -0.068),
    (180.0, -0.072),
];

impl HeadFrame {
    pub(super) fn new(lm: &Landmarks) -> Result<HeadFrame, String> {
        let all = [
            lm.eye_left,
            lm.eye_right,
            lm.ear_left,
            lm.ear_right,
            lm.nose_bridge,
            lm.crown,
        ];
        if all.iter().any(|p| !p.is_finite()) {
            return Err(format!("landmarks are not finite: {lm:?}"));
        }
        if lm.eye_left.x <= lm.eye_right.x || lm.ear_left.x <= lm.ear_right.x {
            return Err(format!(
                "landmarks are not in the canonical frame (the subject's left must be +X): \
                 eyes at x = {} / {}, ears at x = {} / {}",
                lm.eye_left.x, lm.eye_right.x, lm.ear_left.x, lm.ear_right.x
            ));
        }
        let eye = lm.eye_centre();
        let crown_above = lm.crown.y - eye.y;
        if crown_above < 0.05 {
            return Err(format!(
                "the crown (y = {}) must be at least 5 cm above the eyes (y = {})",
                lm.crown.y, eye.y
            ));
        }
        let k = (crown_above / REF_CROWN_ABOVE_EYES).clamp(0.8, 1.25);
        let mid_x = 0.5 * (lm.ear_left.x + lm.ear_right.x);
        let eye_half = 0.5 * (lm.eye_left.x - lm.eye_right.x);
        Ok(HeadFrame {
            mid_x,
            eye_y: eye.y,
            eye_z: eye.z,
            ear_front_z: lm.ear_left.z.min(lm.ear_right.z),
            ear_mid_z: 0.5 * (lm.ear_left.z + lm.ear_right.z),
            ear_y: 0.5 * (lm.ear_left.y + lm.ear_right.y),
            ears: [lm.ear_left, lm.ear_right],
            crown: lm.crown,
            k,
            face_half_width: eye_half + 0.035 * k,
            face_bottom: eye.y - 0.25 * k,
            face_top: eye.y + 0.045 * k,
        })
    }

    fn azimuth_deg(&self, p: Vec3) -> f32 {
        let a = libm::atan2(
            (p.x - self.mid_x).abs() as f64,
            (p.z - self.ear_mid_z) as f64,
        );
        a.to_degrees() as f32
    }

    fn hairline_y(&self, p: Vec3) -> f32 {
        let phi = self.azimuth_deg(p);
        let mut h = HAIRLINE[HAIRLINE.len() - 1].1;
        for w in HAIRLINE.windows(2) {
            let ((a0, h0), (a1, h1)) = (w[0], w[1]);
            if phi <= a1 {
                let t = ((phi - a0) / (a1 - a0)).clamp(0.0, 1.0);
                h = h0 + (h1 - h0) * t;
                break;
            }
        }
        self.eye_y + self.k * h
    }

    fn on_ear(&self, p: Vec3) -> bool {
        self.ears.iter().any(|ear| {
            let side = (ear.x - self.mid_x).signum();
            if (p.x - self.mid_x) * side < 0.5 * (ear.x - self.mid_x).abs() {
                return false;
            }
            let dy = (p.y - (ear.y - 0.018 * self.k)) / (0.036 * self.k);
            let dz = (p.z - (ear.z + 0.010 * self.k)) / (0.026 * self.k);
            dy * dy + dz * dz < 1.0
        })
    }

    pub(super) fn in_face(&self, p: Vec3) -> bool {
        p.z > self.ear_front_z
            && (p.x - self.mid_x).abs() < self.face_half_width
            && p.y > self.face_bottom
            && p.y < self.face_top
    }

    /// The nearest point outside the face keep-out, leaving it sideways or upwards (never
    /// backwards, which is into the head, nor downwards, which is in front of the neck).
    pub(super) fn out_of_face(&self, p: Vec3) -> Vec3 {
        const EPS: f32 = 1e-4;
        let dx = p.x - self.mid_x;
        let side = if dx < 0.0 { -1.0 } else { 1.0 };
        let sideways = Vec3::new(self.mid_x + side * (self.face_half_width + EPS), p.y, p.z);
        let up = Vec3::new(p.x, self.face_top + EPS, p.z);
        if up.distance_squared(p) < sideways.distance_squared(p) {
            up
        } else {
            sideways
        }
    }

    pub(super) fn in_scalp(&self, p: Vec3) -> bool {
        p.y >= self.hairline_y(p) && !self.on_ear(p) && !self.in_face(p)
    }
}

/// The skin as the strands see it: vertices with unit normals and a grid for nearest-vertex
/// queries.
pub(super) struct Skin {
    pub(super) positions: Vec<Vec3>,
    pub(super) normals: Vec<Vec3>,
    /// Vertices on an open edge (where a head file cuts the neck, chest or arms): their
    /// normals do not tell inside from outside, so nothing is pushed out along them.
    boundary: Vec<bool>,
    pub(super) grid: PointGrid,
}

impl Skin {
    pub(super) fn new(surface: &HeadSurface) -> Result<Skin, String> {
        if surface.positions.len() != surface.normals.len() {
            return Err(format!(
                "head surface has {} positions but {} normals",
                surface.positions.len(),
                surface.normals.len()
            ));
        }
        let n = surface.positions.len();
        if let Some(t) = surface
            .triangles
            .iter()
            .find(|t| t.iter().any(|&v| v as usize >= n))
        {
            return Err(format!(
                "head surface triangle {t:?} indexes past its {n} vertices"
            ));
        }
        let normals: Vec<Vec3> = surface
            .normals
            .iter()
            .map(|n| n.try_normalize().unwrap_or(Vec3::ZERO))
            .collect();
        let usable: Vec<u32> = (0..n)
            .filter(|&i| surface.positions[i].is_finite() && normals[i] != Vec3::ZERO)
            .map(|i| i as u32)
            .collect();
        if usable.len() < 3 || surface.triangles.is_empty() {
            return Err(
                "head surface has no usable skin (needs triangles with finite vertices and \
                 normals)"
                    .into(),
            );
        }
        let mut edges: Vec<(u32, u32)> = surface
            .triangles
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        edges.sort_unstable();
        let mut boundary = vec![false; n];
        let mut i = 0;
        while i < edges.len() {
            let mut j = i + 1;
            while j < edges.len() && edges[j] == edges[i] {
                j += 1;
            }
            if j - i == 1 {
                boundary[edges[i].0 as usize] = true;
                boundary[edges[i].1 as usize] = true;
            }
            i = j;
        }
        let grid = PointGrid::new(&surface.positions, &usable, 0.008, PROBE_RANGE);
        Ok(Skin {
            positions: surface.positions.clone(),
            normals,
            boundary,
            grid,
        })
    }

    /// Height of `p` above the tangent plane of its nearest skin vertex, that vertex's normal
    /// and whether it is on an open edge; `None` in free space (no vertex within
    /// [`PROBE_RANGE`]).
    pub(super) fn probe_vertex(&self, p: Vec3) -> Option<(f32, Vec3, bool)> {
        let (i, _) = self.grid.nearest(p, PROBE_RANGE)?;
        let i = i as usize;
        let (v, n) = (self.positions[i], self.normals[i]);
        Some(((p - v).dot(n), n, self.boundary[i]))
    }

    pub(super) fn probe(&self, p: Vec3) -> Probe {
        self.probe_vertex(p).map(|(h, n, _)| (h, n))
    }
}

/// Height above the nearest skin vertex's tangent plane and that vertex's normal; `None` in
/// free space.
pub(super) type Probe = Option<(f32, Vec3)>;

#[derive(Clone, Copy, Debug)]
pub(super) struct Root {
    pub(super) pos: Vec3,
    pub(super) normal: Vec3,
}

/// Area-uniform points on the triangles that `region` touches (at a vertex or the centroid),
/// kept when `accept(point, normal)` holds, until `count` are found or the attempts run out.
pub(super) fn sample_roots(
    surface: &HeadSurface,
    skin: &Skin,
    count: usize,
    rng: &mut Rng,
    region: impl Fn(Vec3) -> bool,
    mut accept: impl FnMut(Vec3, Vec3) -> bool,
) -> Vec<Root> {
    let mut tris: Vec<[usize; 3]> = Vec::new();
    let mut cdf: Vec<f64> = Vec::new();
    let mut total = 0.0f64;
    for t in &surface.triangles {
        let [a, b, c] = t.map(|v| v as usize);
        let [pa, pb, pc] = [a, b, c].map(|v| surface.positions[v]);
        if !(pa.is_finite() && pb.is_finite() && pc.is_finite()) {
            continue;
        }
        let centroid = (pa + pb + pc) / 3.0;
        if ![pa, pb, pc, centroid].into_iter().any(&region) {
            continue;
        }
        let area = 0.5 * (pb - pa).cross(pc - pa).length() as f64;
        if area > 0.0 && area.is_finite() {
            total += area;
            tris.push([a, b, c]);
            cdf.push(total);
        }
    }
    let mut roots = Vec::with_capacity(count);
    if tris.is_empty() {
        return roots;
    }
    let max_attempts = count * 12 + 256;
    for _ in 0..max_attempts {
        if roots.len() == count {
            break;
        }
        let x = rng.f64() * total;
        let t = cdf.partition_point(|&c| c <= x).min(tris.len() - 1);
        let [a, b, c] = tris[t];
        let r1 = rng.f32().sqrt();
        let r2 = rng.f32();
        let (wa, wb, wc) = (1.0 - r1, r1 * (1.0 - r2), r1 * r2);
        let [pa, pb, pc] = [a, b, c].map(|v| surface.positions[v]);
        let p = pa * wa + pb * wb + pc * wc;
        let face_n = (pb - pa).cross(pc - pa).normalize_or(Vec3::Y);
        let n = (skin.normals[a] * wa + skin.normals[b] * wb + skin.normals[c] * wc)
            .try_normalize()
            .unwrap_or(face_n);
        if !accept(p, n) {
            continue;
        }
        let mut pos = p + n * ROOT_LIFT;
        // On coarse meshes the nearest vertex's tangent plane can lie above the triangle.
        if let Some((h, vn)) = skin.probe(pos) {
            if h < 0.0003 {
                pos += vn * (0.0003 - h).min(0.0003);
            }
        }
        roots.push(Root { pos, normal: n });
    }
    roots
}

/// The skin triangles around one spot, for placing points exactly on the flat triangles the
/// renderer draws (the nearest-vertex planes of the coarse head meshes can be mm off).
pub(super) struct LocalSkin {
    triangles: Vec<[Vec3; 3]>,
    /// Outward unit normal of each triangle.
    normals: Vec<Vec3>,
    /// Each triangle's bounding box (min, max): a lower bound on its distance that lets
    /// [`LocalSkin::closest`] skip most triangles exactly.
    bounds: Vec<(Vec3, Vec3)>,
}

impl LocalSkin {
    pub(super) fn new(surface: &HeadSurface, skin: &Skin, centre: Vec3, radius: f32) -> LocalSkin {
        let mut triangles = Vec::new();
        let mut normals = Vec::new();
        for t in &surface.triangles {
            let idx = t.map(|v| v as usize);
            let tri = idx.map(|v| surface.positions[v]);
            if !tri.iter().any(|p| p.distance(centre) < radius) {
                continue;
            }
            let Some(mut n) = (tri[1] - tri[0]).cross(tri[2] - tri[0]).try_normalize() else {
                continue;
            };
            let vertex_normals: Vec3 = idx.iter().map(|&v| skin.normals[v]).sum();
            if n.dot(vertex_normals) < 0.0 {
                n = -n;
            }
            triangles.push(tri);
            normals.push(n);
        }
        // 1 µm of slack: a closest point computed in f32 may round a few nm outside its
        // triangle's exact box, and the bound must never exceed its distance.
        let slack = Vec3::splat(1e-6);
        let bounds = triangles
            .iter()
            .map(|t| {
                let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
                (lo - slack, hi + slack)
            })
            .collect();
        LocalSkin {
            triangles,
            normals,
            bounds,
        }
    }

    /// Closest point on these triangles and the outward normal of its triangle; of equally
    /// close triangles, the first.
    pub(super) fn closest(&self, p: Vec3) -> Option<(Vec3, Vec3)> {
        if !p.is_finite() {
            return self.closest_brute(p);
        }
        // The triangle whose box is nearest gives a first bound; then every triangle whose box
        // is no farther than the best so far is measured, in order. A skipped triangle is
        // strictly farther than the answer, so the answer is the brute force's, bit for bit.
        let box_d2 =
            |(lo, hi): &(Vec3, Vec3)| (*lo - p).max(p - *hi).max(Vec3::ZERO).length_squared();
        let first = self
            .bounds
            .iter()
            .map(box_d2)
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))?
            .0;
        let c = closest_on_triangle(p, self.triangles[first]);
        let mut best = (c.distance_squared(p), first, c);
        for (i, b) in self.bounds.iter().enumerate() {
            if box_d2(b) > best.0 || i == first {
                continue;
            }
            let c = closest_on_triangle(p, self.triangles[i]);
            let d2 = c.distance_squared(p);
            if d2 < best.0 || (d2 == best.0 && i < best.1) {
                best = (d2, i, c);
            }
        }
        Some((best.2, self.normals[best.1]))
    }

    /// [`LocalSkin::closest`] by measuring every triangle.
    fn closest_brute(&self, p: Vec3) -> Option<(Vec3, Vec3)> {
        let mut best: Option<(f32, Vec3, Vec3)> = None;
        for (tri, n) in self.triangles.iter().zip(&self.normals) {
            let c = closest_on_triangle(p, *tri);
            let d2 = c.distance_squared(p);
            if best.is_none_or(|(b, _, _)| d2 < b) {
                best = Some((d2, c, *n));
            }
        }
        best.map(|(_, c, n)| (c, n))
    }

    /// Whether the segment a→b crosses one of these triangles.
    pub(super) fn crossed_by(&self, a: Vec3, b: Vec3) -> bool {
        let (lo, hi) = (a.min(b), a.max(b));
        // A triangle whose box misses the segment's box cannot cross it.
        let near = |(tlo, thi): &(Vec3, Vec3)| tlo.cmple(hi).all() && thi.cmpge(lo).all();
        self.triangles
            .iter()
            .zip(&self.bounds)
            .any(|(tri, bounds)| near(bounds) && segment_crosses(*tri, a, b))
    }
}

/// Whether the segment a→b crosses the triangle (Möller–Trumbore).
fn segment_crosses([p0, p1, p2]: [Vec3; 3], a: Vec3, b: Vec3) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A bumpy sphere of radius 10 cm, each triangle listed twice (exact ties).
    fn bumpy_sphere() -> HeadSurface {
        let (rings, sectors) = (40u32, 64u32);
        let mut positions = Vec::new();
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..sectors {
                let phi = std::f32::consts::TAU * j as f32 / sectors as f32;
                let r = 0.1 + 0.002 * (5.0 * phi).sin() * (3.0 * theta).cos();
                positions.push(
                    Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.cos(),
                        theta.sin() * phi.sin(),
                    ) * r,
                );
            }
        }
        let normals = positions.iter().map(|p| p.normalize()).collect();
        let mut triangles = Vec::new();
        for i in 0..rings {
            for j in 0..sectors {
                let v = |a: u32, b: u32| a * sectors + b % sectors;
                let quad = [v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)];
                for t in [[quad[0], quad[2], quad[1]], [quad[0], quad[3], quad[2]]] {
                    triangles.push(t);
                    triangles.push(t);
                }
            }
        }
        HeadSurface {
            positions,
            normals,
            triangles,
        }
    }

    #[test]
    fn closest_is_the_brute_force_answer() {
        let surface = bumpy_sphere();
        let skin = Skin::new(&surface).unwrap();
        let centre = Vec3::new(0.0, 0.05, 0.08);
        let local = LocalSkin::new(&surface, &skin, centre, 0.05);
        assert!(local.triangles.len() > 500, "{}", local.triangles.len());
        let mut rng = Rng::new(7, 0, 0);
        let mut checked = 0;
        for k in 0..20_000 {
            let dir = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            // On the surface, just off it, inside it and well away from it.
            let p = centre + dir * [0.001, 0.01, 0.03, 0.2][k % 4];
            let p = [p, p.normalize() * 0.1, p * 0.9, p][k % 4];
            assert_eq!(local.closest(p), local.closest_brute(p), "query {k} at {p}");
            checked += 1;
        }
        // Vertices exactly: many triangles tie at distance zero.
        for &p in surface
            .positions
            .iter()
            .filter(|p| p.distance(centre) < 0.04)
        {
            assert_eq!(local.closest(p), local.closest_brute(p), "vertex {p}");
            checked += 1;
        }
        assert!(checked > 20_000);
        // Segments from off the surface through it, along it and beside it.
        let mut crossings = 0;
        for k in 0..20_000 {
            let dir = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            let a = (centre + dir * 0.03).normalize() * rng.range(0.095, 0.105);
            let b = a + Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ) * [0.002, 0.01][k % 2];
            let brute = local.triangles.iter().any(|t| segment_crosses(*t, a, b));
            assert_eq!(local.crossed_by(a, b), brute, "segment {k}: {a} to {b}");
            crossings += usize::from(brute);
        }
        assert!(
            (2000..18_000).contains(&crossings),
            "{crossings} of 20000 segments cross"
        );
        let nan = Vec3::new(f32::NAN, 0.0, 0.0);
        assert_eq!(
            format!("{:?}", local.closest(nan)),
            format!("{:?}", local.closest_brute(nan))
        );
    }
}
