//! Eyelid margins: where the lids meet the eyeball, the line the eyelashes grow from.
//!
//! The built-in head meshes do not mark their lid margins, and the MakeHuman skin is closed
//! over the eye socket (the lids fold back into it), so the margin is not an open edge of the
//! mesh. It is found the way a frontal photograph shows it: rays cast towards −Z on a 0.25 mm
//! grid around each eyeball see eyeball in front of skin inside the eye opening and skin
//! outside. The opening is the connected region of eyeball pixels around the eye centre; in
//! each grid column its top and bottom pixels, refined by bisection to the first skin hit, are
//! points of the upper and lower margin.
//!
//! The search runs on the head's neutral pose, where every built-in head has its eyes open,
//! and remembers each margin point as a skin triangle and barycentric coordinates. The
//! expression's morphs then carry the points with the lids ([`LidPoints::place`]): a blinking
//! head keeps its margins, and its lashes, on the closed lids.

use glam::{Vec2, Vec3};

use crate::landmarks::HeadSurface;

/// Half-width of the square searched around each eye centre, metres.
const HALF_EXTENT: f32 = 0.02;
/// Grid spacing of the rays, metres.
const STEP: f32 = 0.00025;
/// The opening must contain a pixel this close to the eye centre (in the frontal view).
const CENTRE_RADIUS: f32 = 0.004;
/// Side of the cells the triangles are binned into, metres.
const CELL: f32 = 0.001;

/// A point on the skin: a triangle of a [`HeadSurface`] and barycentric weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub triangle: u32,
    pub bary: [f32; 3],
}

/// One eye's margins on the neutral pose, ordered from the inner corner (medial, towards the
/// nose) to the outer one.
#[derive(Clone, Debug, PartialEq)]
pub struct LidPoints {
    /// +1 for the subject's left eye (+X), −1 for the right.
    pub side: f32,
    pub upper: Vec<SurfacePoint>,
    pub lower: Vec<SurfacePoint>,
}

/// One eye's margins placed on a (possibly morphed) skin, medial to lateral, canonical frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EyeLids {
    pub side: f32,
    pub upper: Vec<Vec3>,
    pub lower: Vec<Vec3>,
}

impl LidPoints {
    /// The margins on `surface`, which must have the triangles of the surface they were found
    /// on (the same head, any expression). Points on a missing triangle are skipped.
    pub fn place(&self, surface: &HeadSurface) -> EyeLids {
        let at = |p: &SurfacePoint| -> Option<Vec3> {
            let t = surface.triangles.get(p.triangle as usize)?;
            let mut out = Vec3::ZERO;
            for (v, w) in t.iter().zip(p.bary) {
                out += *surface.positions.get(*v as usize)? * w;
            }
            out.is_finite().then_some(out)
        };
        EyeLids {
            side: self.side,
            upper: self.upper.iter().filter_map(at).collect(),
            lower: self.lower.iter().filter_map(at).collect(),
        }
    }
}

/// Triangles projected onto the frontal (xy) plane, binned for ray casts along −Z.
struct FrontalView {
    triangles: Vec<([Vec3; 3], u32)>,
    cells: Vec<Vec<u32>>,
    origin: Vec2,
    dim: usize,
}

/// The front-most hit of a ray along −Z: depth, triangle id and barycentrics.
#[derive(Clone, Copy)]
struct Hit {
    z: f32,
    id: u32,
    bary: [f32; 3],
}

impl FrontalView {
    fn new(centre: Vec3, triangles: Vec<([Vec3; 3], u32)>) -> FrontalView {
        let dim = (2.0 * HALF_EXTENT / CELL).ceil() as usize + 1;
        let origin = Vec2::new(centre.x - HALF_EXTENT, centre.y - HALF_EXTENT);
        let mut cells = vec![Vec::new(); dim * dim];
        let cell_of = |v: f32| (v / CELL).floor().clamp(0.0, (dim - 1) as f32) as usize;
        for (k, (tri, _)) in triangles.iter().enumerate() {
            let lo = tri[0].min(tri[1]).min(tri[2]).truncate() - origin;
            let hi = tri[0].max(tri[1]).max(tri[2]).truncate() - origin;
            if hi.x < 0.0 || hi.y < 0.0 || lo.x > 2.0 * HALF_EXTENT || lo.y > 2.0 * HALF_EXTENT {
                continue;
            }
            for cy in cell_of(lo.y)..=cell_of(hi.y) {
                for cx in cell_of(lo.x)..=cell_of(hi.x) {
                    cells[cy * dim + cx].push(k as u32);
                }
            }
        }
        FrontalView {
            triangles,
            cells,
            origin,
            dim,
        }
    }

    fn front_hit(&self, p: Vec2) -> Option<Hit> {
        let c = (p - self.origin) / CELL;
        if c.x < 0.0 || c.y < 0.0 || c.x >= self.dim as f32 || c.y >= self.dim as f32 {
            return None;
        }
        let cell = &self.cells[c.y as usize * self.dim + c.x as usize];
        let mut best: Option<Hit> = None;
        for &k in cell {
            let (tri, id) = &self.triangles[k as usize];
            let [a, b, c] = tri.map(|v| v.truncate());
            let det = (b - a).perp_dot(c - a);
            if det.abs() < 1e-14 {
                continue;
            }
            let w1 = (p - a).perp_dot(c - a) / det;
            let w2 = (b - a).perp_dot(p - a) / det;
            let w0 = 1.0 - w1 - w2;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let z = w0 * tri[0].z + w1 * tri[1].z + w2 * tri[2].z;
            if best.is_none_or(|h| z > h.z) {
                best = Some(Hit {
                    z,
                    id: *id,
                    bary: [w0, w1, w2],
                });
            }
        }
        best
    }
}

/// Finds one eye's margins. `eye` holds the eyeball's triangles (any eye material), `centre`
/// its centre and `side` which eye it is; `skin` is the neutral skin.
pub fn find_lids(
    skin: &HeadSurface,
    eye: &[[Vec3; 3]],
    centre: Vec3,
    side: f32,
) -> Result<LidPoints, String> {
    let near = |tri: &[Vec3; 3]| tri.iter().any(|p| p.distance(centre) < 1.5 * HALF_EXTENT);
    let mut skin_tris = Vec::new();
    for (k, t) in skin.triangles.iter().enumerate() {
        let tri = t.map(|v| skin.positions.get(v as usize).copied().unwrap_or(Vec3::NAN));
        if tri.iter().all(|p| p.is_finite()) && near(&tri) {
            skin_tris.push((tri, k as u32));
        }
    }
    let eye_tris: Vec<_> = eye
        .iter()
        .filter(|t| t.iter().all(|p| p.is_finite()) && near(t))
        .map(|t| (*t, 0))
        .collect();
    if eye_tris.is_empty() {
        return Err(format!(
            "no eyeball triangles within 3 cm of the eye at {centre}"
        ));
    }
    let skin_view = FrontalView::new(centre, skin_tris);
    let eye_view = FrontalView::new(centre, eye_tris);
    let open = |p: Vec2| match (eye_view.front_hit(p), skin_view.front_hit(p)) {
        (Some(e), Some(s)) => e.z > s.z,
        (Some(_), None) => true,
        _ => false,
    };

    let n = (2.0 * HALF_EXTENT / STEP) as usize + 1;
    let origin = Vec2::new(centre.x - HALF_EXTENT, centre.y - HALF_EXTENT);
    let at = |i: usize, j: usize| origin + Vec2::new(i as f32, j as f32) * STEP;
    let mut mask = vec![false; n * n];
    for j in 0..n {
        for i in 0..n {
            mask[j * n + i] = open(at(i, j));
        }
    }
    let c = n / 2;
    let reach = (CENTRE_RADIUS / STEP) as usize;
    let seed = (c.saturating_sub(reach)..=(c + reach).min(n - 1))
        .flat_map(|j| (c.saturating_sub(reach)..=(c + reach).min(n - 1)).map(move |i| (i, j)))
        .filter(|&(i, j)| mask[j * n + i])
        .min_by_key(|&(i, j)| (i.abs_diff(c)).pow(2) + (j.abs_diff(c)).pow(2));
    let Some(seed) = seed else {
        return Err(format!(
            "no eyeball visible from the front within {} mm of the eye centre {centre} (closed \
             or covered eye in the neutral pose)",
            CENTRE_RADIUS * 1000.0
        ));
    };

    // The opening: the 4-connected region of open pixels around the seed.
    let mut region = vec![false; n * n];
    let mut stack = vec![seed];
    region[seed.1 * n + seed.0] = true;
    while let Some((i, j)) = stack.pop() {
        if i == 0 || j == 0 || i == n - 1 || j == n - 1 {
            return Err(format!(
                "the eye opening at {centre} reaches the edge of the {} mm search square: the \
                 skin does not close around the eyeball",
                2.0 * HALF_EXTENT * 1000.0
            ));
        }
        for (a, b) in [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)] {
            if mask[b * n + a] && !region[b * n + a] {
                region[b * n + a] = true;
                stack.push((a, b));
            }
        }
    }

    // The first skin hit between an open point and a closed one, by bisection.
    let edge = |inside: Vec2, outside: Vec2| -> Option<SurfacePoint> {
        let (mut a, mut b) = (inside, outside);
        for _ in 0..12 {
            let m = (a + b) * 0.5;
            if open(m) {
                a = m;
            } else {
                b = m;
            }
        }
        skin_view.front_hit(b).map(|h| SurfacePoint {
            triangle: h.id,
            bary: h.bary,
        })
    };
    let mut upper = Vec::new();
    let mut lower = Vec::new();
    for i in 0..n {
        let rows: Vec<usize> = (0..n).filter(|&j| region[j * n + i]).collect();
        let (Some(&bottom), Some(&top)) = (rows.first(), rows.last()) else {
            continue;
        };
        if let Some(p) = edge(at(i, top), at(i, top + 1)) {
            upper.push(p);
        }
        if let Some(p) = edge(at(i, bottom), at(i, bottom - 1)) {
            lower.push(p);
        }
    }
    // Medial first: the grid runs in +X, which is medial → lateral for the left eye only.
    let medial_first = |pts: &mut Vec<SurfacePoint>| {
        let x = |p: &SurfacePoint| {
            let t = skin.triangles[p.triangle as usize];
            (0..3)
                .map(|k| skin.positions[t[k] as usize].x * p.bary[k])
                .sum::<f32>()
        };
        if let (Some(a), Some(b)) = (pts.first(), pts.last()) {
            if (x(b) - x(a)) * side < 0.0 {
                pts.reverse();
            }
        }
    };
    medial_first(&mut upper);
    medial_first(&mut lower);
    if upper.len() < 8 || lower.len() < 8 {
        return Err(format!(
            "the eye opening at {centre} has skin above and below it in only {} grid columns \
             (0.25 mm each): the lids do not frame the eyeball",
            upper.len().min(lower.len())
        ));
    }
    Ok(LidPoints { side, upper, lower })
}
