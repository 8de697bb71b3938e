//! Glasses: two procedural frame styles, the anchors of any glasses model, and its fit to a head.
//!
//! A glasses model is described by its [`GlassesAnchors`], found from geometry alone (the lens
//! triangles and the temples), so a downloaded model fits the same way as the procedural ones.
//! [`fit_glasses`] is the rigid-plus-uniform-scale placement; [`place_glasses`] adds what one
//! matrix cannot do: bending each temple at its hinge so its ear bend lands on that ear, as an
//! optician adjusts a frame (heads differ far more in width and depth behind the eyes than in
//! eye distance).

use glam::{DVec3, Mat3, Mat4, Vec2, Vec3};
use lightfarm_render::scene::{
    shapes, Instance, Material, MaterialModel, Mesh, ObjectClass, Scene,
};

use crate::{HeadSurface, Landmarks, SubjectError};

/// The two procedural frame styles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FrameStyle {
    /// Circular lenses in a thin gold wire frame.
    Round,
    /// Rounded-rectangle lenses in a thick dark acetate frame.
    Rectangular,
}

/// Where a glasses model touches a face, in the model's own frame (after node transforms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlassesAnchors {
    /// Area-weighted centroid of the lens on the wearer's left.
    pub lens_left: Vec3,
    pub lens_right: Vec3,
    /// Where the left temple rests on the ear: the centre line of the temple at its ear bend,
    /// or its rearmost part when the temple is straight.
    pub ear_left: Vec3,
    pub ear_right: Vec3,
    /// Unit normal of the lens plane, pointing away from the temples (the way the wearer looks).
    pub forward: Vec3,
    /// Unit vector in the lens plane, perpendicular to the line through the lens centres.
    pub up: Vec3,
}

impl GlassesAnchors {
    /// Unit vector towards the wearer's left.
    pub fn left(&self) -> Vec3 {
        self.up.cross(self.forward)
    }

    pub fn lens_centre(&self) -> Vec3 {
        (self.lens_left + self.lens_right) * 0.5
    }
}

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

// Models and classes set here live in memory only: `write_glb` writes glTF factors, so the
// generated files (and their catalog hashes) do not carry them; `glasses_materials` sets them
// again on whatever glasses file is loaded.

fn gold() -> Material {
    Material {
        name: "frame_metal_gold".to_string(),
        // Linear reflectance of gold at normal incidence.
        base_color: [1.0, 0.766, 0.336, 1.0],
        metallic: 1.0,
        roughness: 0.3,
        model: MaterialModel::Metal,
        class: ObjectClass::Frame,
        ..Material::default()
    }
}

fn dark_plastic(name: &str, roughness: f32) -> Material {
    Material {
        name: name.to_string(),
        base_color: [0.018, 0.012, 0.010, 1.0],
        metallic: 0.0,
        roughness,
        model: MaterialModel::Plastic,
        class: ObjectClass::Frame,
        ..Material::default()
    }
}

fn silicone() -> Material {
    Material {
        name: "nose_pad".to_string(),
        base_color: [0.75, 0.75, 0.72, 1.0],
        metallic: 0.0,
        roughness: 0.35,
        model: MaterialModel::Plastic,
        class: ObjectClass::Frame,
        ..Material::default()
    }
}

fn lens_material() -> Material {
    Material {
        name: "lens".to_string(),
        base_color: [1.0; 4],
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        ior: 1.5,
        model: MaterialModel::Lens,
        class: ObjectClass::Lens,
        ..Material::default()
    }
}

/// Gives a glasses model's materials their models and classes: the lenses ([`lens_materials`])
/// become `lens` / class lens, the rest frame parts (class frame): `metal` when the file's
/// metalness is at least 0.5, else `plastic` (silicone pads included). Both presets keep the
/// file's colour and roughness, so the frames look as before. A material whose file carries
/// `extras.lightfarm` keeps its model; its class is still the part's role.
pub fn glasses_materials(scene: &mut Scene) {
    let is_lens = lens_materials(scene);
    for (m, lens) in scene.materials.iter_mut().zip(is_lens) {
        let (model, class) = if lens {
            (MaterialModel::Lens, ObjectClass::Lens)
        } else if m.metallic >= 0.5 {
            (MaterialModel::Metal, ObjectClass::Frame)
        } else {
            (MaterialModel::Plastic, ObjectClass::Frame)
        };
        if m.model == MaterialModel::Gltf {
            m.apply_model(model);
        }
        m.class = class;
    }
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

#[derive(Default)]
struct MeshBuilder {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    indices: Vec<u32>,
}

impl MeshBuilder {
    fn vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        self.positions.push(p);
        self.normals.push(n);
        (self.positions.len() - 1) as u32
    }

    /// Winds the triangle so its face agrees with its vertex normals, which every builder here
    /// sets outward; the renderer and the closed-mesh tests rely on consistent winding.
    fn tri(&mut self, a: u32, b: u32, c: u32) {
        let p = |i: u32| self.positions[i as usize];
        let face = (p(b) - p(a)).cross(p(c) - p(a));
        let normals =
            self.normals[a as usize] + self.normals[b as usize] + self.normals[c as usize];
        if face.dot(normals) < 0.0 {
            self.indices.extend([a, c, b]);
        } else {
            self.indices.extend([a, b, c]);
        }
    }

    /// `a b c d` in order around the quad.
    fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.tri(a, b, c);
        self.tri(a, c, d);
    }

    fn finish(self, name: &str) -> Mesh {
        let n = self.positions.len();
        Mesh {
            name: name.to_string(),
            positions: self.positions.iter().map(|p| p.to_array()).collect(),
            normals: self.normals.iter().map(|p| p.to_array()).collect(),
            uvs: vec![[0.0; 2]; n],
            tangents: vec![[0.0; 4]; n],
            triangle_materials: vec![0; self.indices.len() / 3],
            indices: self.indices,
            morph_targets: Vec::new(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Anchors
// ---------------------------------------------------------------------------------------------

/// Temples are what lies behind this fraction of the model's depth; nose pads and hinges do not.
const TEMPLE_DEPTH_FRACTION: f32 = 0.3;
/// Depth bins of the temple profile the ear bend is found on.
const TEMPLE_BINS: usize = 48;
/// A temple whose profile rises less than this fraction of its length above the chord from its
/// front to its end has no ear bend worth the name; its rearmost part is the rest point.
const EAR_BEND_MIN_RISE: f32 = 0.04;

fn asset_error(reason: impl Into<String>) -> SubjectError {
    SubjectError::Asset {
        asset: "glasses model".to_string(),
        reason: reason.into(),
    }
}

/// Which materials are lenses: the transmissive ones, narrowed to those named "lens" when
/// transmissive nose pads also exist (the Khronos sunglasses have them), or by name alone when a
/// file carries no transmission.
fn lens_materials(scene: &Scene) -> Vec<bool> {
    let named = |m: &Material| m.name.to_ascii_lowercase().contains("lens");
    let transmissive: Vec<bool> = scene
        .materials
        .iter()
        .map(|m| m.transmission > 0.0)
        .collect();
    let both: Vec<bool> = scene
        .materials
        .iter()
        .map(|m| m.transmission > 0.0 && named(m))
        .collect();
    if both.iter().any(|&b| b) {
        both
    } else if transmissive.iter().any(|&b| b) {
        transmissive
    } else {
        scene.materials.iter().map(named).collect()
    }
}

/// Finds a model's anchors from its geometry: the lens triangles (see [`lens_materials`]), the
/// lens plane (least-variance axis of the lens surface), the temples (what lies far behind it),
/// and +Y only to tell up from down (glTF's convention; −Y-up files would come out upside down
/// and left-right mirrored, Z-up files are detected).
pub fn glasses_anchors(scene: &Scene) -> Result<GlassesAnchors, SubjectError> {
    let is_lens = lens_materials(scene);
    let mut lens: Vec<[Vec3; 3]> = Vec::new();
    let mut other: Vec<[Vec3; 3]> = Vec::new();
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        let world: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| inst.transform.transform_point3(Vec3::from(*p)))
            .collect();
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let corner = |k: usize| world.get(tri[k] as usize).copied();
            let (Some(a), Some(b), Some(c)) = (corner(0), corner(1), corner(2)) else {
                return Err(asset_error(format!(
                    "mesh '{}' has a vertex index out of range",
                    mesh.name
                )));
            };
            let material = mesh.triangle_materials.get(t).copied().unwrap_or(u32::MAX);
            if is_lens.get(material as usize).copied().unwrap_or(false) {
                lens.push([a, b, c]);
            } else {
                other.push([a, b, c]);
            }
        }
    }
    if lens.is_empty() {
        return Err(asset_error(
            "no lens triangles: no material has KHR_materials_transmission > 0 or a name \
             containing \"lens\"",
        ));
    }
    if other.is_empty() {
        return Err(asset_error(
            "no frame or temple triangles besides the lenses, so the temples cannot be found",
        ));
    }
    let stats =
        SurfaceStats::of(&lens).ok_or_else(|| asset_error("the lens triangles have no area"))?;
    let centre = stats.centroid;
    let normal = stats.least_variance_axis();

    // The temples reach far behind the lenses; the frame front hardly at all in front.
    let (lo, hi) = other
        .iter()
        .flatten()
        .map(|p| (*p - centre).dot(normal))
        .fold((0.0f32, 0.0f32), |(lo, hi), d| (lo.min(d), hi.max(d)));
    let forward = if -lo > hi { normal } else { -normal };

    let hint = if Vec3::Y.dot(forward).abs() < 0.9 {
        Vec3::Y
    } else {
        // A Z-up file looks along ±Y; +Z is then its up.
        Vec3::Z
    };
    let up0 = (hint - forward * hint.dot(forward)).normalize();
    let left0 = up0.cross(forward);
    let (l, r) = split_centroids(&lens, centre, left0)
        .ok_or_else(|| asset_error("all lens triangles lie on one side; need two lenses"))?;
    let across = (l - r) - forward * (l - r).dot(forward);
    let left = across.try_normalize().unwrap_or(left0);
    let up = forward.cross(left);
    // Split again across the refined axis so a tilted model is halved where its lenses are.
    let (lens_left, lens_right) = split_centroids(&lens, centre, left).unwrap_or((l, r));

    let frame = Frame {
        origin: (lens_left + lens_right) * 0.5,
        left,
        up,
        forward,
    };
    let local: Vec<[Vec3; 3]> = other.iter().map(|t| t.map(|p| frame.coords(p))).collect();
    let max_depth = local.iter().flatten().map(|c| c.z).fold(0.0f32, f32::max);
    let temple: Vec<[Vec3; 3]> = local
        .into_iter()
        .filter(|t| t.iter().all(|c| c.z > TEMPLE_DEPTH_FRACTION * max_depth))
        .collect();
    let ear_left = ear_point(&temple, 1.0)
        .ok_or_else(|| asset_error("no temple reaches back on the wearer's left"))?;
    let ear_right = ear_point(&temple, -1.0)
        .ok_or_else(|| asset_error("no temple reaches back on the wearer's right"))?;
    Ok(GlassesAnchors {
        lens_left,
        lens_right,
        ear_left: frame.point(ear_left),
        ear_right: frame.point(ear_right),
        forward,
        up,
    })
}

/// Orthonormal axes at the lens centre: coordinates are (lateral, height, depth behind).
struct Frame {
    origin: Vec3,
    left: Vec3,
    up: Vec3,
    forward: Vec3,
}

impl Frame {
    fn coords(&self, p: Vec3) -> Vec3 {
        let d = p - self.origin;
        Vec3::new(d.dot(self.left), d.dot(self.up), -d.dot(self.forward))
    }

    fn point(&self, c: Vec3) -> Vec3 {
        self.origin + self.left * c.x + self.up * c.y - self.forward * c.z
    }
}

/// The rest point of one temple (`side` +1 = left) in frame coordinates. The temple's top and
/// bottom outlines are traced per depth bin from points along its triangle edges (vertices
/// alone would leave bins holding only half a cross-section); the rest point is the middle of
/// the bin whose top rises most above the chord from the temple's front to its end, i.e. where
/// it bends down around the ear, or of the rearmost bin when the temple is straight.
fn ear_point(temple: &[[Vec3; 3]], side: f32) -> Option<Vec3> {
    let tris: Vec<&[Vec3; 3]> = temple
        .iter()
        .filter(|t| t.iter().all(|c| c.x * side > 0.0))
        .collect();
    let (lo, hi) = tris
        .iter()
        .flat_map(|t| t.iter())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), c| {
            (lo.min(c.z), hi.max(c.z))
        });
    if tris.is_empty() {
        return None;
    }
    let width = ((hi - lo) / TEMPLE_BINS as f32).max(1e-6);
    // Per bin: lowest and highest height, lowest and highest lateral offset.
    let mut bins = vec![
        [
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY
        ];
        TEMPLE_BINS
    ];
    for t in &tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let steps =
                (((b.z - a.z).abs() / (0.5 * width)).ceil() as usize).clamp(1, 4 * TEMPLE_BINS);
            for i in 0..=steps {
                let c = a + (b - a) * (i as f32 / steps as f32);
                let bin = (((c.z - lo) / width) as usize).min(TEMPLE_BINS - 1);
                let e = &mut bins[bin];
                *e = [e[0].min(c.y), e[1].max(c.y), e[2].min(c.x), e[3].max(c.x)];
            }
        }
    }
    // (depth, top, middle point) of each bin that holds part of the temple.
    let profile: Vec<(f32, f32, Vec3)> = bins
        .iter()
        .enumerate()
        .filter(|(_, e)| e[0] <= e[1])
        .map(|(i, e)| {
            let depth = lo + (i as f32 + 0.5) * width;
            (
                depth,
                e[1],
                Vec3::new(0.5 * (e[2] + e[3]), 0.5 * (e[0] + e[1]), depth),
            )
        })
        .collect();
    let (first, last) = (*profile.first()?, *profile.last()?);
    let length = last.0 - first.0;
    if length <= 0.0 {
        return Some(last.2);
    }
    let rise =
        |b: &(f32, f32, Vec3)| b.1 - (first.1 + (last.1 - first.1) * (b.0 - first.0) / length);
    let knee = profile
        .iter()
        .max_by(|a, b| rise(a).total_cmp(&rise(b)))
        .copied()
        .unwrap_or(last);
    Some(if rise(&knee) > EAR_BEND_MIN_RISE * length {
        knee.2
    } else {
        last.2
    })
}

/// Area-weighted centroids of the triangles on the +`axis` and −`axis` sides of `centre`.
fn split_centroids(tris: &[[Vec3; 3]], centre: Vec3, axis: Vec3) -> Option<(Vec3, Vec3)> {
    let mut sums = [(Vec3::ZERO, 0.0f32); 2];
    for t in tris {
        let g = (t[0] + t[1] + t[2]) / 3.0;
        let area = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        let k = usize::from((g - centre).dot(axis) < 0.0);
        sums[k].0 += g * area;
        sums[k].1 += area;
    }
    let [(pl, al), (pr, ar)] = sums;
    (al > 0.0 && ar > 0.0).then(|| (pl / al, pr / ar))
}

/// Area moments of a triangle set.
struct SurfaceStats {
    centroid: Vec3,
    /// Covariance of the surface about its centroid (per unit area).
    covariance: [[f64; 3]; 3],
}

impl SurfaceStats {
    fn of(tris: &[[Vec3; 3]]) -> Option<SurfaceStats> {
        // Moments about the first vertex keep f64 sums well conditioned far from the origin.
        let origin = tris.first()?[0].as_dvec3();
        let mut area = 0.0f64;
        let mut first = DVec3::ZERO;
        let mut second = [[0.0f64; 3]; 3];
        for t in tris {
            let [a, b, c] = t.map(|v| v.as_dvec3() - origin);
            let w = 0.5 * (b - a).cross(c - a).length();
            let s = a + b + c;
            area += w;
            first += s * (w / 3.0);
            // Exact second moment of a triangle: A/12 (a aᵀ + b bᵀ + c cᵀ + s sᵀ).
            for (i, row) in second.iter_mut().enumerate() {
                for (j, m) in row.iter_mut().enumerate() {
                    *m += w / 12.0 * (a[i] * a[j] + b[i] * b[j] + c[i] * c[j] + s[i] * s[j]);
                }
            }
        }
        if area.is_nan() || area <= 0.0 {
            return None;
        }
        let mean = first / area;
        let mut covariance = [[0.0; 3]; 3];
        for (i, row) in covariance.iter_mut().enumerate() {
            for (j, m) in row.iter_mut().enumerate() {
                *m = second[i][j] / area - mean[i] * mean[j];
            }
        }
        Some(SurfaceStats {
            centroid: (origin + mean).as_vec3(),
            covariance,
        })
    }

    /// Unit eigenvector of the smallest eigenvalue (the normal of a best-fit plane).
    fn least_variance_axis(&self) -> Vec3 {
        let (values, vectors) = symmetric_eigen(self.covariance);
        let k = (0..3)
            .min_by(|&a, &b| values[a].total_cmp(&values[b]))
            .unwrap_or(2);
        DVec3::new(vectors[0][k], vectors[1][k], vectors[2][k])
            .as_vec3()
            .normalize_or(Vec3::Z)
    }
}

/// Cyclic Jacobi eigen-decomposition of a symmetric 3×3 matrix: eigenvalues and the
/// eigenvectors as the columns of the second result.
fn symmetric_eigen(m: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let scale = a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2);
        if off <= 1e-30 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (rp, rq) = (row[p], row[q]);
                row[p] = c * rp - s * rq;
                row[q] = s * rp + c * rq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * row_p[k] - s * row_q[k]);
            a[q] = std::array::from_fn(|k| s * row_p[k] + c * row_q[k]);
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

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
