//! Glasses: the two procedural frame styles and the materials of any glasses model (see the parent module).

#[allow(unused_imports)]
use super::*;

// ---------------------------------------------------------------------------------------------
// Procedural models
// ---------------------------------------------------------------------------------------------

/// Half the distance between the lens centres (frame PD 64 mm).
const LENS_OFFSET_X: f32 = 0.032;
/// Lenses are 2 mm slabs so a dielectric renderer refracts through two surfaces.
const LENS_HALF_THICKNESS: f32 = 0.001;
/// Radius of the lens's base curve; real lenses are menisci, not flat plates.
const LENS_BASE_RADIUS: f32 = 0.15;
/// Vertices on each lens outline; rings of the lens faces between outline and centre.
const OUTLINE_POINTS: usize = 64;
const LENS_RINGS: usize = 3;

/// Round style: lens radius and the wire.
const ROUND_LENS_RADIUS: f32 = 0.024;
const WIRE_RADIUS: f32 = 0.0009;
/// Rectangular style: lens half sizes and corner radius, and the acetate rim cross-section.
const RECT_LENS_HALF: Vec2 = Vec2::new(0.026, 0.018);
/// Upper outer, upper nasal, lower nasal, lower outer: the lower nasal corner is cut back so
/// the rim clears the side of the nose.
const RECT_CORNER_RADII: [f32; 4] = [0.008, 0.008, 0.015, 0.009];
const ACETATE_RIM_WIDTH: f32 = 0.005;
const ACETATE_HALF_DEPTH: f32 = 0.002;
/// Keeps frame and lens apart so the lens stays a separate closed dielectric.
const LENS_GAP: f32 = 0.0001;

/// Temple path shared by both styles: the hinge, where the ear bend starts, and the bend.
const TEMPLE_BEND_DEPTH: f32 = 0.100;
const TEMPLE_BEND_X: f32 = 0.069;
const TEMPLE_BEND_Y: f32 = -0.002;
const EAR_BEND_RADIUS: f32 = 0.02;
const EAR_BEND_DEGREES: f64 = 60.0;

/// A glasses model in the glasses-local frame: lens centres at (±0.032, 0, ~0), lenses facing
/// +Z, temples running back along −Z to an ear bend at z ≈ −0.10, +Y up, the wearer's left at
/// +X. Materials: `frame_*`, `lens` (clear dielectric: transmission 1, ior 1.5), and for the
/// metal frame `nose_pad` and `temple_tip`. The output is bit-identical on every platform (only
/// IEEE-exact arithmetic), so the generated assets keep their catalog hashes.
pub fn procedural_glasses(style: FrameStyle) -> Scene {
    let mut lenses = MeshBuilder::default();
    for side in [1.0, -1.0] {
        let outline = lens_outline(style, side);
        lens_slab(&mut lenses, Vec2::new(side * LENS_OFFSET_X, 0.0), &outline);
    }
    let mut scene = Scene::default();
    match style {
        FrameStyle::Round => {
            let parts = round_frame();
            scene.add_mesh_instance(parts.frame.finish("frame"), gold(), Mat4::IDENTITY);
            scene.add_mesh_instance(lenses.finish("lenses"), lens_material(), Mat4::IDENTITY);
            scene.add_mesh_instance(parts.pads.finish("nose_pads"), silicone(), Mat4::IDENTITY);
            scene.add_mesh_instance(
                parts.tips.finish("temple_tips"),
                dark_plastic("temple_tip", 0.35),
                Mat4::IDENTITY,
            );
        }
        FrameStyle::Rectangular => {
            let frame = rect_frame();
            scene.add_mesh_instance(
                frame.finish("frame"),
                dark_plastic("frame_acetate", 0.4),
                Mat4::IDENTITY,
            );
            scene.add_mesh_instance(lenses.finish("lenses"), lens_material(), Mat4::IDENTITY);
        }
    }
    scene
}

/// sin and cos from IEEE-exact operations only: libm's sinf/cosf differ in the last bit between
/// platforms, which would change the generated files and so their catalog hashes.
fn sin_cos(angle: f64) -> (f32, f32) {
    let tau = std::f64::consts::TAU;
    let x = angle - (angle / tau).round() * tau;
    let x2 = x * x;
    let (mut s, mut c) = (x, 1.0);
    let (mut ts, mut tc) = (x, 1.0);
    // |x| <= pi, so 15 terms of each series are below f64 precision.
    for n in 1..=15 {
        let n = f64::from(n);
        ts *= -x2 / ((2.0 * n) * (2.0 * n + 1.0));
        tc *= -x2 / ((2.0 * n - 1.0) * (2.0 * n));
        s += ts;
        c += tc;
    }
    (s as f32, c as f32)
}

#[derive(Clone, Copy)]
struct OutlinePoint {
    /// Relative to the lens centre.
    p: Vec2,
    /// Outward unit normal in the lens plane.
    n: Vec2,
}

/// Counter-clockwise seen from +Z, starting at +X.
fn circle_outline(radius: f32) -> Vec<OutlinePoint> {
    (0..OUTLINE_POINTS)
        .map(|k| {
            let (s, c) = sin_cos(std::f64::consts::TAU * k as f64 / OUTLINE_POINTS as f64);
            let n = Vec2::new(c, s);
            OutlinePoint { p: n * radius, n }
        })
        .collect()
}

/// The outline of the lens on `side` (+1 = wearer's left, centred at +X).
fn lens_outline(style: FrameStyle, side: f32) -> Vec<OutlinePoint> {
    let left = match style {
        FrameStyle::Round => circle_outline(ROUND_LENS_RADIUS),
        FrameStyle::Rectangular => rounded_rect_outline(RECT_LENS_HALF, RECT_CORNER_RADII),
    };
    // The lens centre is its area centroid (where the anchors will find it), not the centre of
    // an asymmetric outline's bounding box.
    let centroid = polygon_centroid(&left);
    // Mirrored for the right lens; winding does not matter, MeshBuilder::tri orients by normal.
    let mirror = Vec2::new(side, 1.0);
    left.into_iter()
        .map(|o| OutlinePoint {
            p: (o.p - centroid) * mirror,
            n: o.n * mirror,
        })
        .collect()
}

/// Area centroid of a closed polygon (shoelace formula).
fn polygon_centroid(outline: &[OutlinePoint]) -> Vec2 {
    let n = outline.len();
    let (mut area, mut sum) = (0.0f32, Vec2::ZERO);
    for k in 0..n {
        let (a, b) = (outline[k].p, outline[(k + 1) % n].p);
        let cross = a.perp_dot(b);
        area += cross;
        sum += (a + b) * cross;
    }
    if area == 0.0 {
        Vec2::ZERO
    } else {
        sum / (3.0 * area)
    }
}

/// Rounded rectangle of half sizes `half` with corner radii (upper outer, upper nasal, lower
/// nasal, lower outer) for a lens whose nasal side is −X; counter-clockwise from +X, points
/// evenly spaced by arc length so the long sides keep the lens curvature.
fn rounded_rect_outline(half: Vec2, radii: [f32; 4]) -> Vec<OutlinePoint> {
    let (a, b) = (half.x, half.y);
    let [r0, r1, r2, r3] = radii;
    // (start, end, outward normal) of the four sides and (centre, radius) of the four corners,
    // in counter-clockwise order from the right side.
    let sides = [
        (Vec2::new(a, -b + r3), Vec2::new(a, b - r0), Vec2::X),
        (Vec2::new(a - r0, b), Vec2::new(-a + r1, b), Vec2::Y),
        (Vec2::new(-a, b - r1), Vec2::new(-a, -b + r2), Vec2::NEG_X),
        (Vec2::new(-a + r2, -b), Vec2::new(a - r3, -b), Vec2::NEG_Y),
    ];
    let corners = [
        (Vec2::new(a - r0, b - r0), r0),
        (Vec2::new(-a + r1, b - r1), r1),
        (Vec2::new(-a + r2, -b + r2), r2),
        (Vec2::new(a - r3, -b + r3), r3),
    ];
    let arc = |r: f32| 0.5 * std::f32::consts::PI * r;
    let perimeter: f32 = (0..4)
        .map(|q| sides[q].0.distance(sides[q].1) + arc(corners[q].1))
        .sum();
    // Start where the right side crosses y = 0 so the first point is at +X.
    let start = b - r3;
    (0..OUTLINE_POINTS)
        .map(|k| {
            let mut s = start + (k as f32 / OUTLINE_POINTS as f32) * perimeter;
            for q in 0..8 {
                let (from, to, normal) = sides[q % 4];
                let length = from.distance(to);
                if s <= length || q == 7 {
                    let t = (s / length).clamp(0.0, 1.0);
                    return OutlinePoint {
                        p: from + (to - from) * t,
                        n: normal,
                    };
                }
                s -= length;
                let (centre, radius) = corners[q % 4];
                if s <= arc(radius) {
                    let angle =
                        ((q % 4) as f64 + f64::from(s / arc(radius))) * std::f64::consts::FRAC_PI_2;
                    let (sn, cs) = sin_cos(angle);
                    let n = Vec2::new(cs, sn);
                    return OutlinePoint {
                        p: centre + n * radius,
                        n,
                    };
                }
                s -= arc(radius);
            }
            OutlinePoint {
                p: Vec2::new(a, 0.0),
                n: Vec2::X,
            }
        })
        .collect()
}

/// Depth of the lens surfaces at `q` (relative to the lens centre): a paraboloid meniscus.
fn lens_sag(q: Vec2) -> f32 {
    -q.dot(q) / (2.0 * LENS_BASE_RADIUS)
}

/// A closed lens: front and back surfaces joined by an edge band, normals outward.
fn lens_slab(b: &mut MeshBuilder, centre: Vec2, outline: &[OutlinePoint]) {
    let h = LENS_HALF_THICKNESS;
    for face in [1.0f32, -1.0] {
        let at = |q: Vec2| Vec3::new(centre.x + q.x, centre.y + q.y, lens_sag(q) + face * h);
        let normal = |q: Vec2| {
            (face * Vec3::new(q.x / LENS_BASE_RADIUS, q.y / LENS_BASE_RADIUS, 1.0)).normalize()
        };
        let middle = b.vertex(at(Vec2::ZERO), normal(Vec2::ZERO));
        let rings: Vec<Vec<u32>> = (1..=LENS_RINGS)
            .map(|r| {
                let scale = r as f32 / LENS_RINGS as f32;
                outline
                    .iter()
                    .map(|o| b.vertex(at(o.p * scale), normal(o.p * scale)))
                    .collect()
            })
            .collect();
        let n = outline.len();
        for k in 0..n {
            let k1 = (k + 1) % n;
            b.tri(middle, rings[0][k], rings[0][k1]);
            for r in 1..LENS_RINGS {
                let (inner, outer) = (&rings[r - 1], &rings[r]);
                b.quad(inner[k], outer[k], outer[k1], inner[k1]);
            }
        }
    }
    let n = outline.len();
    let edge: Vec<(u32, u32)> = outline
        .iter()
        .map(|o| {
            let z = lens_sag(o.p);
            let normal = o.n.extend(0.0);
            let xy = centre + o.p;
            (
                b.vertex(xy.extend(z + h), normal),
                b.vertex(xy.extend(z - h), normal),
            )
        })
        .collect();
    for k in 0..n {
        let k1 = (k + 1) % n;
        b.quad(edge[k].0, edge[k].1, edge[k1].1, edge[k1].0);
    }
}

/// One cross-section point of a swept tube: offset and unit normal in the (n, b) plane.
#[derive(Clone, Copy)]
struct ProfilePoint {
    at: Vec2,
    normal: Vec2,
}

fn circle_profile(radius: f32, segments: usize) -> Vec<ProfilePoint> {
    (0..segments)
        .map(|k| {
            let (s, c) = sin_cos(std::f64::consts::TAU * k as f64 / segments as f64);
            let normal = Vec2::new(c, s);
            ProfilePoint {
                at: normal * radius,
                normal,
            }
        })
        .collect()
}

/// Rounded rectangle centred at `centre`, three points per corner.
fn rounded_rect_profile(centre: Vec2, half: Vec2, corner: f32) -> Vec<ProfilePoint> {
    let inner = half - Vec2::splat(corner);
    let signs = [
        Vec2::new(1.0, 1.0),
        Vec2::new(-1.0, 1.0),
        Vec2::new(-1.0, -1.0),
        Vec2::new(1.0, -1.0),
    ];
    let mut out = Vec::with_capacity(12);
    for (q, sign) in signs.iter().enumerate() {
        for step in 0..3 {
            let angle = (q as f64 + step as f64 / 2.0) * std::f64::consts::FRAC_PI_2;
            let (s, c) = sin_cos(angle);
            let normal = Vec2::new(c, s);
            out.push(ProfilePoint {
                at: centre + inner * *sign + normal * corner,
                normal,
            });
        }
    }
    out
}

/// Sweeps `profile` along `path`; `axes[i]` = (n, b) spans the cross-section at `path[i]`.
/// Open tubes are capped so every part is a closed surface.
fn sweep(
    b: &mut MeshBuilder,
    path: &[Vec3],
    axes: &[(Vec3, Vec3)],
    profile: &[ProfilePoint],
    closed: bool,
) {
    let rings: Vec<Vec<u32>> = path
        .iter()
        .zip(axes)
        .map(|(p, (n, bn))| {
            profile
                .iter()
                .map(|q| {
                    b.vertex(
                        *p + *n * q.at.x + *bn * q.at.y,
                        (*n * q.normal.x + *bn * q.normal.y).normalize(),
                    )
                })
                .collect()
        })
        .collect();
    let m = profile.len();
    let segments = if closed { path.len() } else { path.len() - 1 };
    for i in 0..segments {
        let i1 = (i + 1) % path.len();
        for j in 0..m {
            let j1 = (j + 1) % m;
            b.quad(rings[i][j], rings[i1][j], rings[i1][j1], rings[i][j1]);
        }
    }
    if closed || path.len() < 2 {
        return;
    }
    let last = path.len() - 1;
    for (end, towards) in [(0, 1), (last, last - 1)] {
        let normal = (path[end] - path[towards]).normalize();
        let (n, bn) = axes[end];
        let centre = b.vertex(path[end], normal);
        let cap: Vec<u32> = profile
            .iter()
            .map(|q| b.vertex(path[end] + n * q.at.x + bn * q.at.y, normal))
            .collect();
        for j in 0..m {
            b.tri(centre, cap[j], cap[(j + 1) % m]);
        }
    }
}

/// Cross-section axes along an open path: n is `reference` made perpendicular to the path.
fn path_axes(path: &[Vec3], reference: Vec3) -> Vec<(Vec3, Vec3)> {
    (0..path.len())
        .map(|i| {
            let a = path[i.saturating_sub(1)];
            let c = path[(i + 1).min(path.len() - 1)];
            let t = (c - a).normalize();
            let n = (reference - t * reference.dot(t)).normalize();
            (n, t.cross(n))
        })
        .collect()
}

fn open_tube(b: &mut MeshBuilder, path: &[Vec3], reference: Vec3, profile: &[ProfilePoint]) {
    let axes = path_axes(path, reference);
    sweep(b, path, &axes, profile, false);
}

fn bezier(p0: Vec3, p1: Vec3, p2: Vec3, segments: usize) -> Vec<Vec3> {
    (0..=segments)
        .map(|k| {
            let t = k as f32 / segments as f32;
            let u = 1.0 - t;
            p0 * (u * u) + p1 * (2.0 * u * t) + p2 * (t * t)
        })
        .collect()
}

/// The temple of one side (`side` = +1 left, −1 right) from `hinge` back to the ear bend and
/// down around it: the straight bar, then the bend as a circular arc.
fn temple_path(hinge: Vec3, side: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let bend = Vec3::new(side * TEMPLE_BEND_X, TEMPLE_BEND_Y, -TEMPLE_BEND_DEPTH);
    let bar: Vec<Vec3> = (0..=16)
        .map(|k| hinge + (bend - hinge) * (k as f32 / 16.0))
        .collect();
    let along = (bend - hinge).normalize();
    let down = (Vec3::NEG_Y - along * Vec3::NEG_Y.dot(along)).normalize();
    let arc: Vec<Vec3> = (0..=10)
        .map(|k| {
            let angle = EAR_BEND_DEGREES.to_radians() * k as f64 / 10.0;
            let (s, c) = sin_cos(angle);
            bend + down * (EAR_BEND_RADIUS * (1.0 - c)) + along * (EAR_BEND_RADIUS * s)
        })
        .collect();
    (bar, arc)
}

/// An ellipsoidal nose pad facing `facing`, half sizes (thickness, height, width).
fn nose_pad(b: &mut MeshBuilder, centre: Vec3, facing: Vec3, half: Vec3) {
    let sphere = shapes::icosphere(1.0, 2);
    let height_axis = (Vec3::Y - facing * Vec3::Y.dot(facing)).normalize();
    let width_axis = facing.cross(height_axis);
    let base = b.positions.len() as u32;
    for p in &sphere.positions {
        let u = Vec3::from(*p);
        let at = centre
            + facing * (u.z * half.x)
            + height_axis * (u.y * half.y)
            + width_axis * (u.x * half.z);
        let normal =
            (facing * (u.z / half.x) + height_axis * (u.y / half.y) + width_axis * (u.x / half.z))
                .normalize();
        b.vertex(at, normal);
    }
    for t in sphere.indices.chunks_exact(3) {
        b.tri(base + t[0], base + t[1], base + t[2]);
    }
}

struct RoundParts {
    frame: MeshBuilder,
    pads: MeshBuilder,
    tips: MeshBuilder,
}

fn round_frame() -> RoundParts {
    let mut frame = MeshBuilder::default();
    let mut pads = MeshBuilder::default();
    let mut tips = MeshBuilder::default();
    let wire = circle_profile(WIRE_RADIUS, 8);
    let rim_offset = WIRE_RADIUS + LENS_GAP;
    let rim_radius = ROUND_LENS_RADIUS + rim_offset;
    let edge_z = lens_sag(Vec2::new(ROUND_LENS_RADIUS, 0.0));
    for side in [1.0f32, -1.0] {
        let outline = lens_outline(FrameStyle::Round, side);
        let cx = side * LENS_OFFSET_X;
        let path: Vec<Vec3> = outline
            .iter()
            .map(|o| {
                Vec3::new(
                    cx + o.p.x + o.n.x * rim_offset,
                    o.p.y + o.n.y * rim_offset,
                    edge_z,
                )
            })
            .collect();
        let axes: Vec<(Vec3, Vec3)> = outline.iter().map(|o| (o.n.extend(0.0), Vec3::Z)).collect();
        sweep(&mut frame, &path, &axes, &wire, true);

        // End piece from the rim's outer side, a little above centre, back to the hinge.
        let (s, c) = sin_cos(12f64.to_radians());
        let rim_point = Vec3::new(cx + side * rim_radius * c, rim_radius * s, edge_z);
        let hinge = Vec3::new(side * 0.064, 0.006, -0.006);
        let end_piece = bezier(rim_point, Vec3::new(side * 0.063, 0.0058, edge_z), hinge, 6);
        open_tube(
            &mut frame,
            &end_piece,
            Vec3::Y,
            &circle_profile(1.3 * WIRE_RADIUS, 8),
        );

        // Wire up to where the plastic tip takes over, then the tip around the ear bend.
        let (bar, arc) = temple_path(hinge, side);
        open_tube(&mut frame, &bar[..15], Vec3::X, &wire);
        let tip_path: Vec<Vec3> = bar[13..].iter().chain(&arc[1..]).copied().collect();
        open_tube(&mut tips, &tip_path, Vec3::X, &circle_profile(0.0017, 10));

        // Nose pad on a short arm from the rim's lower inner side.
        let (s, c) = sin_cos(205f64.to_radians());
        let arm_start = Vec3::new(cx + side * rim_radius * c, rim_radius * s, edge_z);
        let facing = Vec3::new(-side * 0.75, 0.0, -0.66).normalize();
        let pad_centre = Vec3::new(side * 0.0105, -0.0065, edge_z - 0.0075);
        let arm_end = pad_centre - facing * 0.0012;
        let arm = bezier(
            arm_start,
            Vec3::new(side * 0.0085, -0.0090, edge_z - 0.004),
            arm_end,
            6,
        );
        open_tube(
            &mut frame,
            &arm,
            Vec3::Z,
            &circle_profile(0.6 * WIRE_RADIUS, 6),
        );
        nose_pad(
            &mut pads,
            pad_centre,
            facing,
            Vec3::new(0.0012, 0.0065, 0.0038),
        );
    }
    // Bridge: an arch between the rims, a little above the lens centres.
    let y = 0.009f32;
    let x = LENS_OFFSET_X - (rim_radius * rim_radius - y * y).sqrt();
    let bridge = bezier(
        Vec3::new(-x, y, edge_z),
        Vec3::new(0.0, 0.0150, edge_z + 0.0015),
        Vec3::new(x, y, edge_z),
        12,
    );
    open_tube(
        &mut frame,
        &bridge,
        Vec3::Z,
        &circle_profile(1.1 * WIRE_RADIUS, 8),
    );
    RoundParts { frame, pads, tips }
}

fn rect_frame() -> MeshBuilder {
    let mut frame = MeshBuilder::default();
    let rim_profile = rounded_rect_profile(
        Vec2::new(LENS_GAP + 0.5 * ACETATE_RIM_WIDTH, 0.0),
        Vec2::new(0.5 * ACETATE_RIM_WIDTH, ACETATE_HALF_DEPTH),
        0.0012,
    );
    let outer_x = LENS_OFFSET_X + RECT_LENS_HALF.x + LENS_GAP + ACETATE_RIM_WIDTH;
    for side in [1.0f32, -1.0] {
        let outline = lens_outline(FrameStyle::Rectangular, side);
        let cx = side * LENS_OFFSET_X;
        let path: Vec<Vec3> = outline
            .iter()
            .map(|o| Vec3::new(cx + o.p.x, o.p.y, lens_sag(o.p)))
            .collect();
        let axes: Vec<(Vec3, Vec3)> = outline.iter().map(|o| (o.n.extend(0.0), Vec3::Z)).collect();
        sweep(&mut frame, &path, &axes, &rim_profile, true);

        // The lug: from inside the rim's outer side, out and back to the hinge.
        let z0 = lens_sag(Vec2::new(RECT_LENS_HALF.x, 0.010));
        let hinge = Vec3::new(side * (outer_x + 0.0015), 0.010, -0.007);
        let lug = bezier(
            Vec3::new(side * (outer_x - 0.003), 0.010, z0),
            Vec3::new(side * (outer_x + 0.0015), 0.010, z0),
            hinge,
            6,
        );
        let lug_profile = rounded_rect_profile(Vec2::ZERO, Vec2::new(0.0045, 0.0019), 0.001);
        open_tube(&mut frame, &lug, Vec3::Y, &lug_profile);

        let (bar, arc) = temple_path(hinge, side);
        let temple: Vec<Vec3> = bar.iter().chain(&arc[1..]).copied().collect();
        let temple_profile = rounded_rect_profile(Vec2::ZERO, Vec2::new(0.0012, 0.0024), 0.0008);
        open_tube(&mut frame, &temple, Vec3::X, &temple_profile);

        // Moulded pads on the rim's lower inner side.
        let facing = Vec3::new(-side * 0.75, 0.0, -0.66).normalize();
        nose_pad(
            &mut frame,
            Vec3::new(side * 0.0075, -0.0055, -0.0040),
            facing,
            Vec3::new(0.0016, 0.0070, 0.0035),
        );
    }
    // Bridge: a block joining the two rims over the nose.
    let z = lens_sag(Vec2::new(RECT_LENS_HALF.x, 0.012));
    let x = LENS_OFFSET_X - RECT_LENS_HALF.x + 0.5 * ACETATE_RIM_WIDTH;
    let bridge = bezier(
        Vec3::new(-x, 0.0115, z),
        Vec3::new(0.0, 0.0135, z + 0.0008),
        Vec3::new(x, 0.0115, z),
        8,
    );
    let bridge_profile =
        rounded_rect_profile(Vec2::ZERO, Vec2::new(ACETATE_HALF_DEPTH, 0.0032), 0.001);
    open_tube(&mut frame, &bridge, Vec3::Z, &bridge_profile);
    frame
}
