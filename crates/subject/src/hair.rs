//! Procedural strand hair and eyebrows, grown on a head's skin.
//!
//! Everything is placed relative to the head's [`Landmarks`] in the canonical frame (metres,
//! +Y up, face towards +Z, subject's left at +X), so one set of rules fits the MakeHuman heads,
//! the ICT heads and scans alike. Heights scale with the crown's height above the eye line
//! (11.7 cm on the reference MakeHuman head), clamped to 0.8..1.25.
//!
//! **Scalp.** A skin point carries hair when it lies above the hairline, off the ears and
//! outside the face keep-out. The hairline is a height above the eye line that depends on the
//! azimuth φ of the point around the vertical axis through the ears' midpoint (0° straight
//! ahead, 90° in the ear plane, 180° at the back), see `HAIRLINE`: 6 cm over the forehead,
//! 4 cm over the temples (φ = 48°), a sideburn in front of the ear that ends 2.2 cm below the
//! eye line, then behind the ears down to the nape, 7.2 cm below the eye line. Each ear is an
//! ellipse in the side view, 7.2 cm tall and 5.2 cm deep, centred 1.8 cm below and 1 cm in
//! front of its landmark (which is on the helix rim), so a rim of bare skin stays around the
//! pinna. The face keep-out is the box in front of the foremost ear, within the eye
//! half-distance + 3.5 cm of the midline, from 25 cm below (the upper chest) to 4.5 cm above
//! the eye line; no root and no strand point is ever inside it (strands that would enter it
//! are moved out sideways or over its top).
//!
//! **Roots** are sampled area-uniformly on the scalp triangles and lifted 0.6 mm along the
//! interpolated normal. Their number is `density` × the style's template count (table below).
//!
//! **Growth.** A strand leaves the skin along its normal and turns, within the style's rise
//! length, into its comb direction: away from the parting (front hairline to crown) for the
//! parted styles, otherwise up and back from the forehead, back over the top and down at the
//! back and sides. Gravity takes over along the strand for the longer styles. Near the scalp
//! a strand slides over it at its own layer height (which gives the hair volume and keeps the
//! ribbons from fighting in depth); where the scalp faces downwards it lets go and hangs. A
//! bob is grown long and cut horizontally (±4 mm) at the height where the mean strand length
//! equals `length_m`: about chin height for 20 cm. A ponytail's strands run over the scalp
//! to their place in a tie 3.5 cm above the ears at the back of the head and then hang as one
//! tail that flares from 1.8 to 4 cm across. Clumping pulls each strand towards its nearest
//! guide strand (one in 24), from nothing at the root to `0.9 × clumping` of the way at the
//! tip. Curl winds a helix around the grown centreline, radius `8 mm × curl` and one turn per
//! `9 cm - 7 cm × curl` (gentle waves to 2 cm coils); the centreline is shortened so that the
//! arc length stays `length_m`.
//!
//! **Collision.** Every point but the root is kept at least 1.5 mm (`MARGIN`) above the
//! tangent plane of its nearest skin vertex, and out of the face keep-out. Where a head file's
//! skin ends (the cut neck, chest or arms) nothing is pushed out along the edge's normals. A
//! strand whose next point cannot be placed ends there: strands are shortened, never
//! lengthened.
//!
//! **Budget.** Strands are rendered as camera-facing ribbons (two triangles a segment), so the
//! template counts trade coverage against triangles. The widths are 2-3x a real fibre's so
//! that a head at 512² pixels from 1 m with a 30° field of view (about 1 mm per pixel) looks
//! covered; they taper linearly to 40 % at the tip. At density 1:
//!
//! | style    | strands | segments ≤ | root width | ribbon triangles ≤ |
//! |----------|--------:|-----------:|-----------:|-------------------:|
//! | buzz     |  80 000 |          2 |    0.15 mm |            320 000 |
//! | short    |  30 000 |         16 |    0.20 mm |            960 000 |
//! | bob      |  22 000 |         24 |    0.18 mm |          1 056 000 |
//! | long     |  14 000 |         40 |    0.18 mm |          1 120 000 |
//! | curly    |  10 000 |         56 |    0.22 mm |          1 120 000 |
//! | ponytail |  14 000 |         40 |    0.18 mm |          1 120 000 |
//!
//! Segments are about 4 mm for short hair, 8 mm for a bob and 12 mm for long hair and
//! ponytails (up to 17 mm for the longest strands, 60 cm + 15 %, to stay in the budget); curly
//! hair gets at least six segments per coil. Per-strand width varies ±15 %.
//!
//! **Determinism.** All randomness comes from SplitMix64 streams keyed by (seed, purpose,
//! index), every loop runs in a fixed order on one thread, and the few transcendental
//! functions are our own series in `dmath`, so the output is bit-identical whatever libm the
//! platform has.

use glam::{Vec2, Vec3};
use lightfarm_render::scene::Mesh;
use lightfarm_scene::expand::HairSample;

use crate::landmarks::{closest_on_triangle, HeadSurface, Landmarks};

/// Minimum height of a strand point above the tangent plane of its nearest skin vertex.
const MARGIN: f32 = 0.0015;
/// One strand in this many is a clump guide.
const GUIDE_EVERY: usize = 24;
/// Longest move clumping may make a point (less than [`PROBE_RANGE`]).
const MAX_CLUMP_PULL: f32 = 0.02;

/// How far above the skin a root sits: close enough to read as growing out of it, far enough
/// that the coarse head meshes' vertex normals do not put it inside.
const ROOT_LIFT: f32 = 0.0006;
/// Tolerance below [`MARGIN`] at which a placed point still counts as outside.
const CLEAR_TOLERANCE: f32 = 0.0003;
/// A strand within this distance above its layer still follows the scalp.
const NEAR: f32 = 0.01;
/// Skin vertices farther than this do not influence a strand point (free space).
const PROBE_RANGE: f32 = 0.03;
/// Fraction of the previous direction kept at each growth step; smooths the strand.
const STIFFNESS: f32 = 0.35;
/// Tip width as a fraction of the root width.
const TIP_WIDTH: f32 = 0.4;
/// Reference height of the crown above the eye line (MakeHuman head 01), metres.
const REF_CROWN_ABOVE_EYES: f32 = 0.117;
const DOWN: Vec3 = Vec3::NEG_Y;

/// Polylines with per-vertex width; strand i owns `points[offsets[i]..offsets[i+1]]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Strands {
    pub points: Vec<Vec3>,
    /// Full fibre (ribbon) width at each point, metres.
    pub widths: Vec<f32>,
    /// `strand_count() + 1` entries, from 0 to `points.len()`.
    pub offsets: Vec<u32>,
}

impl Default for Strands {
    fn default() -> Self {
        Strands {
            points: Vec::new(),
            widths: Vec::new(),
            offsets: vec![0],
        }
    }
}

impl Strands {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    pub fn strand_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Points and widths of strand `i`; empty slices when `i` is out of range or the offsets
    /// are malformed (see [`Strands::validate`]).
    pub fn strand(&self, i: usize) -> (&[Vec3], &[f32]) {
        let (Some(&a), Some(&b)) = (self.offsets.get(i), self.offsets.get(i + 1)) else {
            return (&[], &[]);
        };
        let range = a as usize..b as usize;
        match (self.points.get(range.clone()), self.widths.get(range)) {
            (Some(p), Some(w)) => (p, w),
            _ => (&[], &[]),
        }
    }

    /// Number of polyline segments over all strands.
    pub fn segment_count(&self) -> usize {
        self.offsets
            .windows(2)
            .map(|w| (w[1].saturating_sub(w[0]) as usize).saturating_sub(1))
            .sum()
    }

    /// Checks the invariants: offsets start at 0, never decrease and end at `points.len()`,
    /// every strand has at least 2 points, widths match the points, all points are finite and
    /// all widths finite and positive.
    pub fn validate(&self) -> Result<(), String> {
        if self.offsets.first() != Some(&0) {
            return Err(format!(
                "offsets must start with 0 (got {:?})",
                self.offsets.first()
            ));
        }
        if self.widths.len() != self.points.len() {
            return Err(format!(
                "{} widths for {} points; there must be one width per point",
                self.widths.len(),
                self.points.len()
            ));
        }
        for (i, w) in self.offsets.windows(2).enumerate() {
            if w[1] < w[0] {
                return Err(format!(
                    "offsets decrease at strand {i}: {} then {}",
                    w[0], w[1]
                ));
            }
            if w[1] - w[0] < 2 {
                return Err(format!(
                    "strand {i} has {} point(s); every strand needs at least 2",
                    w[1] - w[0]
                ));
            }
        }
        let last = self.offsets.last().copied().unwrap_or(0) as usize;
        if last != self.points.len() {
            return Err(format!(
                "the last offset is {last} but there are {} points",
                self.points.len()
            ));
        }
        if let Some(i) = self.points.iter().position(|p| !p.is_finite()) {
            return Err(format!("point {i} is not finite: {}", self.points[i]));
        }
        if let Some(i) = self
            .widths
            .iter()
            .position(|w| !(w.is_finite() && *w > 0.0))
        {
            return Err(format!(
                "width {i} is {}; widths must be finite and positive",
                self.widths[i]
            ));
        }
        Ok(())
    }

    /// Camera-facing ribbons: each segment becomes a quad (two triangles, four vertices of its
    /// own) of the local width, lying in the plane that contains the segment and faces `eye`
    /// (the camera position). Vertex normals are perpendicular to the segment and point to the
    /// eye's side; uv is (across 0..1, along root 0 .. tip 1 by arc length); the tangent is the
    /// across direction. This is how strands are rendered until the renderer has a real hair
    /// primitive; the ribbons only face the camera they were built for.
    pub fn ribbon_mesh(&self, eye: Vec3, name: &str) -> Mesh {
        // One quad per segment with its own four vertices: a ribbon shared between segments
        // twists into a bow tie wherever the strand turns through the view direction.
        let segments = self.segment_count();
        let mut positions = Vec::with_capacity(4 * segments);
        let mut normals = Vec::with_capacity(4 * segments);
        let mut uvs = Vec::with_capacity(4 * segments);
        let mut tangents = Vec::with_capacity(4 * segments);
        let mut indices = Vec::with_capacity(6 * segments);
        for i in 0..self.strand_count() {
            let (pts, widths) = self.strand(i);
            let n = pts.len();
            if n < 2 {
                continue;
            }
            let total: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
            let along = |arc: f32, j: usize| {
                if total > 0.0 {
                    (arc / total).min(1.0)
                } else {
                    j as f32 / (n - 1) as f32
                }
            };
            let mut arc = 0.0f32;
            let mut last_tangent = Vec3::Y;
            for j in 0..n - 1 {
                let (a, b) = (pts[j], pts[j + 1]);
                let length = a.distance(b);
                let t = (b - a).try_normalize().unwrap_or(last_tangent);
                last_tangent = t;
                let view = (eye - 0.5 * (a + b)).try_normalize().unwrap_or(Vec3::Z);
                let side = t
                    .cross(view)
                    .try_normalize()
                    .unwrap_or_else(|| any_perpendicular(t));
                // side × t is the part of `view` perpendicular to the segment: it faces the
                // eye, and the triangles below are counter-clockwise seen from there.
                let normal = side.cross(t).try_normalize().unwrap_or(view);
                let (v0, v1) = (along(arc, j), along(arc + length, j + 1));
                arc += length;
                let base = positions.len() as u32;
                for (p, w, v) in [(a, widths[j], v0), (b, widths[j + 1], v1)] {
                    for (u, s) in [(0.0f32, -0.5 * w), (1.0, 0.5 * w)] {
                        positions.push((p + side * s).to_array());
                        normals.push(normal.to_array());
                        uvs.push([u, v]);
                        // glTF: normal × tangent × w must point towards decreasing v; normal ×
                        // side is the strand direction (increasing v), hence w = -1.
                        tangents.push([side.x, side.y, side.z, -1.0]);
                    }
                }
                indices.extend_from_slice(&[
                    base,
                    base + 1,
                    base + 2,
                    base + 1,
                    base + 3,
                    base + 2,
                ]);
            }
        }
        let triangles = indices.len() / 3;
        Mesh {
            name: name.to_string(),
            positions,
            normals,
            uvs,
            tangents,
            indices,
            triangle_materials: vec![0; triangles],
            morph_targets: Vec::new(),
        }
    }

    /// Appends all strands of `other` (hair + eyebrows into one set).
    pub fn extend(&mut self, other: &Strands) {
        if self.offsets.is_empty() {
            self.offsets.push(self.points.len() as u32);
        }
        let base = self.points.len() as u32;
        let first = other.offsets.first().copied().unwrap_or(0);
        self.points.extend_from_slice(&other.points);
        self.widths.extend_from_slice(&other.widths);
        self.offsets.extend(
            other
                .offsets
                .iter()
                .skip(1)
                .map(|&o| base + o.saturating_sub(first)),
        );
    }

    fn push(&mut self, points: &[Vec3], widths: &[f32]) {
        self.points.extend_from_slice(points);
        self.widths.extend_from_slice(widths);
        self.offsets.push(self.points.len() as u32);
    }
}

/// Linear-RGB diffuse colour of a hair fibre from the melanin parameters of Blender's
/// Principled Hair BSDF (Chiang et al. 2016), for the ribbon material until the renderer has a
/// hair BSDF.
///
/// The concentration mapping is Blender's: `c = -ln(1 - melanin)`, split into eumelanin
/// `c (1 - redness)` and pheomelanin `c redness`, and the absorption coefficients (per fibre
/// radius) are Cycles' `bsdf_principled_hair_sigma_from_concentration`:
/// eumelanin (0.506, 0.841, 1.653), pheomelanin (0.343, 0.733, 1.924). (pbrt-v4's
/// `HairBxDF::SigmaAFromConcentration` uses (0.419, 0.697, 1.37) and (0.187, 0.4, 1.05); with
/// those, moving a fixed concentration from eumelanin to pheomelanin narrows the gap between
/// the red and the green/blue absorption, so more redness would give a lighter but *less* red
/// colour.) The absorption is turned into a colour as the transmittance of one
/// pass straight through the fibre, `exp(-2 σ_a)` (diameter 2 in units of the radius),
/// scaled by 0.95 so that white hair is not a perfect reflector. That is an approximation: the
/// real colour of a head of hair comes from many fibres and lobes; this one lands on
/// plausible swatches (melanin 0.2: blond, 0.5: light brown, 0.8: dark chestnut, 0.95: black).
pub fn hair_albedo(melanin: f64, melanin_redness: f64) -> [f32; 3] {
    const EUMELANIN: [f64; 3] = [0.506, 0.841, 1.653];
    const PHEOMELANIN: [f64; 3] = [0.343, 0.733, 1.924];
    let melanin = if melanin.is_finite() {
        melanin.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let redness = if melanin_redness.is_finite() {
        melanin_redness.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let concentration = -dmath::ln((1.0 - melanin).max(1e-4));
    let eu = concentration * (1.0 - redness);
    let pheo = concentration * redness;
    std::array::from_fn(|c| {
        let sigma_a = eu * EUMELANIN[c] + pheo * PHEOMELANIN[c];
        (0.95 * dmath::exp(-2.0 * sigma_a)).max(1e-6) as f32
    })
}

/// The hair styles [`grow_hair`] knows, in the order of `lightfarm_scene::expand::HAIR_RANGES`.
pub const HAIR_STYLES: [&str; 6] = ["buzz", "short", "bob", "long", "curly", "ponytail"];

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Buzz,
    Flow,
    Bob,
    Ponytail,
}

/// Per-style template; see the module documentation for the budget behind the numbers.
struct Style {
    name: &'static str,
    kind: Kind,
    /// Strands at density 1.
    strands: u32,
    max_segments: usize,
    /// Target segment length, metres.
    segment: f32,
    root_width: f32,
    /// Largest height of a strand's layer above the scalp (volume), metres.
    lift: f32,
    /// Arc length over which a strand turns from the skin normal into its comb direction.
    rise: f32,
    /// Weight of gravity against the comb direction once the strand is a few cm long.
    gravity: f32,
    /// Styled hair follows the scalp even where it faces down (no hanging).
    hug: bool,
    parted: bool,
    /// Relative spread of strand lengths (uniform ±).
    length_jitter: f32,
}

const STYLES: [Style; 6] = [
    // Stubble is placed directly (see `Grower::grow_buzz`); the growth fields are unused.
    Style {
        name: "buzz",
        kind: Kind::Buzz,
        strands: 80_000,
        max_segments: 2,
        segment: 0.006,
        root_width: 0.00015,
        lift: 0.0,
        rise: 1.0,
        gravity: 0.0,
        hug: true,
        parted: false,
        length_jitter: 0.15,
    },
    Style {
        name: "short",
        kind: Kind::Flow,
        strands: 30_000,
        max_segments: 16,
        segment: 0.004,
        root_width: 0.0002,
        lift: 0.005,
        rise: 0.004,
        gravity: 0.2,
        hug: true,
        parted: false,
        length_jitter: 0.15,
    },
    Style {
        name: "bob",
        kind: Kind::Bob,
        strands: 22_000,
        max_segments: 24,
        segment: 0.008,
        root_width: 0.00018,
        lift: 0.008,
        rise: 0.004,
        gravity: 0.75,
        hug: false,
        parted: true,
        length_jitter: 0.0,
    },
    Style {
        name: "long",
        kind: Kind::Flow,
        strands: 14_000,
        max_segments: 40,
        segment: 0.012,
        root_width: 0.00018,
        lift: 0.008,
        rise: 0.004,
        gravity: 0.85,
        hug: false,
        parted: true,
        length_jitter: 0.15,
    },
    Style {
        name: "curly",
        kind: Kind::Flow,
        strands: 10_000,
        max_segments: 56,
        segment: 0.008,
        root_width: 0.00022,
        lift: 0.02,
        rise: 0.01,
        gravity: 0.35,
        hug: false,
        parted: false,
        length_jitter: 0.2,
    },
    Style {
        name: "ponytail",
        kind: Kind::Ponytail,
        strands: 14_000,
        max_segments: 40,
        segment: 0.012,
        root_width: 0.00018,
        lift: 0.002,
        rise: 0.003,
        gravity: 1.0,
        hug: true,
        parted: false,
        length_jitter: 0.1,
    },
];

// Random streams; fixed numbers so that adding a stream never changes existing output.
const STREAM_ROOTS: u64 = 1;
const STREAM_STRAND: u64 = 2;
const STREAM_HEAD: u64 = 3;
const STREAM_BROW_ROOTS: u64 = 4;
const STREAM_BROW_STRAND: u64 = 5;

/// Grows the strand hair of `hair` on the scalp of `surface`. `seed` picks the roots and every
/// per-strand variation; the same inputs give bit-identical strands on any machine.
///
/// Errors name the offending parameter: an unknown style (listing the known ones),
/// parameters outside their ranges, or a surface/landmark set that cannot carry hair.
pub fn grow_hair(
    surface: &HeadSurface,
    lm: &Landmarks,
    hair: &HairSample,
    seed: u64,
) -> Result<Strands, String> {
    let style = STYLES
        .iter()
        .find(|s| s.name == hair.style)
        .ok_or_else(|| {
            format!(
                "unknown hair style {:?}; known styles: {}",
                hair.style,
                HAIR_STYLES.join(", ")
            )
        })?;
    let check = |name: &str, v: f64, lo: f64, hi: f64| {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(v as f32)
        } else {
            Err(format!(
                "hair.{name} = {v} is outside [{lo}, {hi}] (style {})",
                style.name
            ))
        }
    };
    let density = check("density", hair.density, 0.0, 1.0)?;
    let length = check("length_m", hair.length_m, 0.0, 1.0)?;
    let curl = check("curl", hair.curl, 0.0, 1.0)?;
    let clumping = check("clumping", hair.clumping, 0.0, 1.0)?;
    if length <= 0.0 {
        return Err(format!(
            "hair.length_m must be positive (style {})",
            style.name
        ));
    }
    let count = (density * style.strands as f32).round() as usize;
    if count == 0 {
        return Ok(Strands::new());
    }
    let frame = HeadFrame::new(lm)?;
    let skin = Skin::new(surface)?;
    let grower = Grower {
        skin: &skin,
        frame: &frame,
        style,
        curl: Curl::new(curl),
        clumping,
        seed,
    };
    let mut rng = Rng::new(seed, STREAM_ROOTS, 0);
    let roots = sample_roots(
        surface,
        &skin,
        count,
        &mut rng,
        |p| frame.in_scalp(p),
        |p, _| frame.in_scalp(p),
    );
    if roots.is_empty() {
        return Err(
            "no skin above the hairline: check that the landmarks belong to this head and that \
             the skin covers the scalp"
                .into(),
        );
    }
    Ok(grower.grow(&roots, length))
}

/// Grows both eyebrows: ~320 short fine strands per brow on the brow ridge, lying almost flat
/// on the skin and pointing away from the midline and slightly up. Returns an empty set (and
/// logs why) when the surface or landmarks are unusable.
///
/// The brow band was measured on the MakeHuman and ICT heads, whose brow ridge (the most
/// forward skin above the eye) lies 1.6-2.4 cm above the eyeball centre: per side, from 1.6 cm
/// inside to 2.4 cm outside the eye centre (scaled by the eye distance / 5.9 cm), with its
/// lower edge 1.2 cm above the eye centre at the inner end, 1.8 cm under the arch (60 % of the
/// way out) and 1.4 cm at the tail, and 1.1 cm thick at the inner end thinning to 4 mm.
pub fn grow_eyebrows(surface: &HeadSurface, lm: &Landmarks, seed: u64) -> Strands {
    match grow_eyebrows_checked(surface, lm, seed) {
        Ok(s) => s,
        Err(reason) => {
            tracing::warn!("no eyebrows grown: {reason}");
            Strands::new()
        }
    }
}

/// Per-brow strand count.
const BROW_STRANDS: usize = 320;
const BROW_ROOT_WIDTH: f32 = 0.00018;

/// Shape of one brow in (u, v): u runs 0 (inner end) .. 1 (tail), v is the height above the
/// eye centre; see [`grow_eyebrows`].
#[derive(Clone, Copy)]
struct Brow {
    eye: Vec3,
    /// +1 for the subject's left brow (+X), -1 for the right.
    side: f32,
    mid_x: f32,
    scale: f32,
}

impl Brow {
    const INNER: f32 = 0.016;
    const SPAN: f32 = 0.040;

    fn u(&self, p: Vec3) -> f32 {
        (self.side * (p.x - self.eye.x) + Self::INNER * self.scale) / (Self::SPAN * self.scale)
    }

    fn arch(u: f32) -> f32 {
        if u < 0.6 {
            smoothstep(0.0, 0.6, u)
        } else {
            1.0 - 0.7 * smoothstep(0.6, 1.0, u)
        }
    }

    /// (lower, upper) height of the band above the eye centre at `u`.
    fn band(&self, u: f32) -> (f32, f32) {
        let lower = self.scale * (0.012 + 0.006 * Self::arch(u));
        let thick = self.scale * (0.011 - 0.007 * smoothstep(0.3, 1.0, u));
        (lower, lower + thick)
    }

    fn contains(&self, p: Vec3) -> bool {
        let u = self.u(p);
        if !(0.0..=1.0).contains(&u) || (p.x - self.mid_x) * self.side <= 0.0 {
            return false;
        }
        let (lo, hi) = self.band(u);
        let v = p.y - self.eye.y;
        v >= lo && v <= hi && p.z > self.eye.z - 0.02
    }

    /// Direction of a hair in the face plane at `u`: up at the inner end, outwards along the
    /// brow, slightly down at the tail.
    fn direction(&self, u: f32) -> Vec3 {
        let angle_deg = if u < 0.3 {
            70.0 - 50.0 * (u / 0.3)
        } else {
            20.0 - 35.0 * ((u - 0.3) / 0.7)
        };
        let (s, c) = dmath::sin_cos((angle_deg as f64).to_radians());
        Vec3::new(self.side * c as f32, s as f32, 0.0)
    }
}

fn grow_eyebrows_checked(
    surface: &HeadSurface,
    lm: &Landmarks,
    seed: u64,
) -> Result<Strands, String> {
    let frame = HeadFrame::new(lm)?;
    let skin = Skin::new(surface)?;
    let scale = (lm.eye_distance() / 0.059).clamp(0.85, 1.15);
    let mut out = Strands::new();
    for (b, (eye, side)) in [(lm.eye_left, 1.0f32), (lm.eye_right, -1.0)]
        .into_iter()
        .enumerate()
    {
        let brow = Brow {
            eye,
            side,
            mid_x: frame.mid_x,
            scale,
        };
        let mut rng = Rng::new(seed, STREAM_BROW_ROOTS, b as u64);
        let roots = sample_roots(
            surface,
            &skin,
            BROW_STRANDS,
            &mut rng,
            |p| brow.contains(p),
            |p, n| {
                // Fewer hairs towards the tail; only skin that faces forwards (the brow ridge,
                // not the underside of the orbit rim).
                let keep = 1.0 - 0.6 * smoothstep(0.6, 1.0, brow.u(p));
                brow.contains(p) && n.z > 0.2 && rng_keep(p, keep)
            },
        );
        let centre = eye + Vec3::new(side * 0.004, 0.019, 0.0) * scale;
        let local = LocalSkin::new(surface, &skin, centre, 0.045 * scale);
        for (i, root) in roots.iter().enumerate() {
            let mut rng = Rng::new(seed, STREAM_BROW_STRAND, (b * BROW_STRANDS + i) as u64);
            if let Some(pts) = grow_brow_hair(&local, &brow, root, &mut rng) {
                let w = BROW_ROOT_WIDTH * rng.range(0.85, 1.15);
                let widths = taper(&pts, w);
                out.push(&pts, &widths);
            }
        }
    }
    Ok(out)
}

/// Deterministic thinning keyed by position, so the root sampler's stream stays independent of
/// how many candidates are thinned out.
fn rng_keep(p: Vec3, keep: f32) -> bool {
    let h =
        mix(p.x.to_bits() as u64 ^ ((p.y.to_bits() as u64) << 21) ^ ((p.z.to_bits() as u64) << 42));
    ((h >> 40) as f32 / 16_777_216.0) < keep
}

fn grow_brow_hair(local: &LocalSkin, brow: &Brow, root: &Root, rng: &mut Rng) -> Option<Vec<Vec3>> {
    const SEGMENTS: usize = 3;
    // A brow hair leaves the skin at a shallow angle and then lies on it.
    let height = |j: usize| 0.00035 + 0.00035 * (j as f32 / SEGMENTS as f32);
    let onto_skin = |p: Vec3, h: f32| local.closest(p).map(|(c, n)| (c + n * h, n));
    let u = brow.u(root.pos).clamp(0.0, 1.0);
    // Shorter hairs at the inner end and the tail, the longest over the arch.
    let len = brow.scale * (0.006 + 0.004 * (1.0 - (2.0 * u - 1.0).abs())) * rng.range(0.85, 1.2);
    let jitter = Vec3::new(0.0, rng.range(-0.2, 0.2), 0.0);
    let dir = (brow.direction(u) + jitter).normalize_or(Vec3::new(brow.side, 0.0, 0.0));
    let ds = len / SEGMENTS as f32;
    let (mut p, mut n) = onto_skin(root.pos, height(0))?;
    let mut pts = Vec::with_capacity(SEGMENTS + 1);
    pts.push(p);
    for j in 1..=SEGMENTS {
        // Outwards means around the head where the brow turns to the side, so the direction
        // is built from the surface's own horizontal and vertical tangents.
        let mut around = Vec3::Y.cross(n).normalize_or(Vec3::X);
        if around.dot(Vec3::new(brow.side, 0.0, -0.5)) < 0.0 {
            around = -around;
        }
        let up = (Vec3::Y - n * n.y).normalize_or(Vec3::Y);
        let along = (around * dir.x.abs() + up * dir.y).normalize_or(around);
        let mut q = p + along * ds;
        for _ in 0..2 {
            (q, n) = onto_skin(q, height(j))?;
        }
        if (q.x - brow.mid_x) * brow.side <= 0.0 {
            break;
        }
        pts.push(q);
        p = q;
    }
    (pts.len() >= 2).then_some(pts)
}

/// The skin triangles around one spot, for placing points exactly on the flat triangles the
/// renderer draws (the nearest-vertex planes of the coarse head meshes can be mm off).
struct LocalSkin {
    triangles: Vec<[Vec3; 3]>,
    /// Outward unit normal of each triangle.
    normals: Vec<Vec3>,
}

impl LocalSkin {
    fn new(surface: &HeadSurface, skin: &Skin, centre: Vec3, radius: f32) -> LocalSkin {
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
        LocalSkin { triangles, normals }
    }

    /// Closest point on these triangles and the outward normal of its triangle.
    fn closest(&self, p: Vec3) -> Option<(Vec3, Vec3)> {
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
}

/// Linear taper from `root_width` at the root to [`TIP_WIDTH`] of it at the tip, by arc length.
fn taper(pts: &[Vec3], root_width: f32) -> Vec<f32> {
    let total: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
    let mut arc = 0.0;
    let mut out = Vec::with_capacity(pts.len());
    for (j, p) in pts.iter().enumerate() {
        if j > 0 {
            arc += p.distance(pts[j - 1]);
        }
        let t = if total > 0.0 {
            (arc / total).min(1.0)
        } else {
            0.0
        };
        out.push(root_width * (1.0 - (1.0 - TIP_WIDTH) * t));
    }
    out
}

/// Where strands may and may not go, relative to the landmarks.
struct HeadFrame {
    mid_x: f32,
    eye_y: f32,
    eye_z: f32,
    /// Foremost ear z: the face keep-out starts there.
    ear_front_z: f32,
    ear_mid_z: f32,
    ear_y: f32,
    ears: [Vec3; 2],
    crown: Vec3,
    k: f32,
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
    fn new(lm: &Landmarks) -> Result<HeadFrame, String> {
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
        let a = dmath::atan2(
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

    fn in_face(&self, p: Vec3) -> bool {
        p.z > self.ear_front_z
            && (p.x - self.mid_x).abs() < self.face_half_width
            && p.y > self.face_bottom
            && p.y < self.face_top
    }

    /// The nearest point outside the face keep-out, leaving it sideways or upwards (never
    /// backwards, which is into the head, nor downwards, which is in front of the neck).
    fn out_of_face(&self, p: Vec3) -> Vec3 {
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

    fn in_scalp(&self, p: Vec3) -> bool {
        p.y >= self.hairline_y(p) && !self.on_ear(p) && !self.in_face(p)
    }
}

/// The skin as the strands see it: vertices with unit normals and a grid for nearest-vertex
/// queries.
struct Skin {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// Vertices on an open edge (where a head file cuts the neck, chest or arms): their
    /// normals do not tell inside from outside, so nothing is pushed out along them.
    boundary: Vec<bool>,
    grid: PointGrid,
}

impl Skin {
    fn new(surface: &HeadSurface) -> Result<Skin, String> {
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
    fn probe_vertex(&self, p: Vec3) -> Option<(f32, Vec3, bool)> {
        let (i, _) = self.grid.nearest(p, PROBE_RANGE)?;
        let i = i as usize;
        let (v, n) = (self.positions[i], self.normals[i]);
        Some(((p - v).dot(n), n, self.boundary[i]))
    }

    fn probe(&self, p: Vec3) -> Probe {
        self.probe_vertex(p).map(|(h, n, _)| (h, n))
    }
}

#[derive(Clone, Copy, Debug)]
struct Root {
    pos: Vec3,
    normal: Vec3,
}

/// Area-uniform points on the triangles that `region` touches (at a vertex or the centroid),
/// kept when `accept(point, normal)` holds, until `count` are found or the attempts run out.
fn sample_roots(
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

/// Curl parameters from `HairSample::curl`.
#[derive(Clone, Copy, Debug)]
struct Curl {
    /// Helix radius, metres.
    amplitude: f32,
    /// Helix pitch along the centreline, metres.
    period: f32,
}

impl Curl {
    fn new(curl: f32) -> Curl {
        Curl {
            amplitude: 0.008 * curl,
            period: 0.09 - 0.07 * curl,
        }
    }

    /// Arc length of the helix per unit centreline length.
    fn stretch(&self) -> f32 {
        let r = std::f32::consts::TAU * self.amplitude / self.period;
        (1.0 + r * r).sqrt()
    }
}

/// Everything one hair set's growth needs.
struct Grower<'a> {
    skin: &'a Skin,
    frame: &'a HeadFrame,
    style: &'a Style,
    curl: Curl,
    clumping: f32,
    seed: u64,
}

/// Per-strand parameters drawn from the strand's own random stream.
#[derive(Clone, Copy, Debug)]
struct StrandPlan {
    root: Root,
    /// Target arc length of the centreline.
    length: f32,
    segments: usize,
    lift: f32,
    comb: Vec3,
    width: f32,
    amplitude: f32,
    period: f32,
    phase: f32,
    /// Ponytail: position in the tail's cross-section, unit disc.
    slot: [f32; 2],
}

impl Grower<'_> {
    fn grow(&self, roots: &[Root], length: f32) -> Strands {
        let parting = self.parting();
        let stretch = self.curl.stretch();
        let mut plans: Vec<StrandPlan> = roots
            .iter()
            .enumerate()
            .map(|(i, root)| self.plan(i, *root, length, stretch, parting))
            .collect();
        let guides = assign_guides(roots);
        let tie = (self.style.kind == Kind::Ponytail).then(|| Tail::new(self.skin, self.frame));
        if let Some(tail) = &tie {
            // Hair keeps its side through the tie, so neighbours on the scalp stay neighbours
            // in the tail.
            for plan in plans.iter_mut() {
                plan.slot = tail.slot(plan.root.pos, Vec2::from(plan.slot).length());
            }
        }

        // Centrelines, and where each strand's curl starts.
        let mut lines: Vec<(Vec<Vec3>, f32)> = match (self.style.kind, &tie) {
            (Kind::Buzz, _) => plans.iter().map(|p| (self.grow_buzz(p), 0.0)).collect(),
            (Kind::Ponytail, Some(tail)) => plans
                .iter()
                .enumerate()
                .map(|(i, p)| self.grow_ponytail(p, &plans[guides[i]], tail))
                .collect(),
            (Kind::Bob, _) => self.grow_bob(&plans, length / stretch),
            _ => plans.iter().map(|p| (self.grow_flow(p), 0.0)).collect(),
        };
        if matches!(self.style.kind, Kind::Flow | Kind::Bob) && self.clumping > 0.0 {
            lines = clump(&lines, &guides, self.clumping);
        }

        let mut out = Strands::new();
        for (i, (line, curl_start)) in lines.iter().enumerate() {
            let plan = &plans[i];
            let guide = &plans[guides[i]];
            let mut pts = if plan.amplitude > 0.0 && line.len() >= 2 {
                // Clumped strands curl in step with their guide, as real curls do.
                let phase = guide.phase + (plan.phase - guide.phase) * (1.0 - self.clumping);
                add_curl(
                    line,
                    *curl_start,
                    plan.amplitude,
                    plan.period,
                    phase,
                    any_perpendicular(guide.root.normal),
                )
            } else {
                line.clone()
            };
            self.settle(&mut pts);
            if pts.len() >= 2 {
                let widths = taper(&pts, plan.width);
                out.push(&pts, &widths);
            }
        }
        out
    }

    /// Parting offset from the midline for parted styles: middle, or 2-3 cm to either side.
    fn parting(&self) -> f32 {
        let mut rng = Rng::new(self.seed, STREAM_HEAD, 0);
        let pick = rng.f32();
        let offset = 0.025 * self.frame.k * rng.range(0.8, 1.2);
        if pick < 0.4 {
            0.0
        } else if pick < 0.7 {
            offset
        } else {
            -offset
        }
    }

    fn plan(&self, i: usize, root: Root, length: f32, stretch: f32, parting: f32) -> StrandPlan {
        let style = self.style;
        let mut rng = Rng::new(self.seed, STREAM_STRAND, i as u64);
        let arc = length * (1.0 + style.length_jitter * rng.range(-1.0, 1.0));
        // Curly strands need about six segments per coil to read as coils.
        let segment = if self.curl.amplitude > 0.0 {
            style.segment.min(self.curl.period * stretch / 6.0)
        } else {
            style.segment
        };
        let segments = ((arc / segment).ceil() as usize).clamp(2, style.max_segments);
        let comb = self.comb(root, parting);
        let jitter = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        let r = rng.f32().sqrt();
        let (s, c) = dmath::sin_cos(rng.range(0.0, std::f32::consts::TAU) as f64);
        StrandPlan {
            root,
            length: arc / stretch,
            segments,
            lift: MARGIN + style.lift * rng.f32(),
            comb: (comb + jitter * 0.2).normalize_or(comb),
            width: style.root_width * rng.range(0.85, 1.15),
            amplitude: self.curl.amplitude * rng.range(0.85, 1.15),
            period: self.curl.period * rng.range(0.9, 1.1),
            phase: rng.range(0.0, std::f32::consts::TAU),
            slot: [r * c as f32, r * s as f32],
        }
    }

    /// Comb direction at a root (not yet made tangent to the scalp).
    fn comb(&self, root: Root, parting: f32) -> Vec3 {
        let f = self.frame;
        if self.style.parted {
            let side = if root.pos.x < f.mid_x + parting {
                -1.0
            } else {
                1.0
            };
            // The parting runs from the front hairline to the crown; behind it the hair falls
            // straight down. Front hair is swept back as well as sideways, around the face.
            let lateral = smoothstep(f.crown.z - 0.07 * f.k, f.crown.z - 0.01 * f.k, root.pos.z);
            let front = smoothstep(0.04, 0.09, root.pos.z - f.ear_mid_z);
            Vec3::new(side * lateral, -0.6, -(0.25 + 1.0 * front))
        } else {
            // Away from a point in front of the forehead below the hairline: up and back at
            // the front, back over the top, down at the back and the sides.
            let source = Vec3::new(f.mid_x, f.eye_y + 0.02 * f.k, f.eye_z + 0.1 * f.k);
            let front = smoothstep(0.03, 0.07, root.pos.z - f.ear_mid_z);
            let away = (root.pos - source).normalize_or(Vec3::NEG_Z);
            away + DOWN * (0.4 * (1.0 - front))
        }
    }

    fn grow_buzz(&self, plan: &StrandPlan) -> Vec<Vec3> {
        let n = plan.root.normal;
        let along = (plan.comb - n * plan.comb.dot(n)).normalize_or(any_perpendicular(n));
        let half = 0.5 * plan.length;
        let d1 = (n + along * 0.3).normalize_or(n);
        let d2 = (n + along * 0.6).normalize_or(n);
        let p1 = plan.root.pos + d1 * half;
        vec![plan.root.pos, p1, p1 + d2 * half]
    }

    /// Strand growth over the scalp and into free space (short, long, curly, and the bob
    /// before its cut).
    fn grow_flow(&self, plan: &StrandPlan) -> Vec<Vec3> {
        let ds = plan.length / plan.segments as f32;
        self.grow_path(plan, plan.segments, ds, |_, _| Steer::Comb)
    }

    /// Steps a strand from its root for at most `steps` segments of length `ds`; `steer(p, s)`
    /// picks the flow at arc length `s`.
    fn grow_path(
        &self,
        plan: &StrandPlan,
        steps: usize,
        ds: f32,
        steer: impl Fn(Vec3, f32) -> Steer,
    ) -> Vec<Vec3> {
        let style = self.style;
        let mut pts = Vec::with_capacity(steps + 1);
        pts.push(plan.root.pos);
        let (mut p, mut d, mut s) = (plan.root.pos, plan.root.normal, 0.0f32);
        let mut probe = self.skin.probe(p);
        for _ in 0..steps {
            let layer = MARGIN + (plan.lift - MARGIN) * smoothstep(0.0, 0.03, s);
            let (mut flow, project) = match steer(p, s) {
                Steer::Stop => break,
                Steer::Towards(dir, project) => (dir, project),
                Steer::Comb => {
                    let gamma = style.gravity * smoothstep(0.0, 0.06, s);
                    let flow = (plan.comb * (1.0 - gamma) + DOWN * gamma).normalize_or(DOWN);
                    (flow, true)
                }
            };
            let mut up = plan.root.normal;
            if let Some((h, n)) = probe {
                up = n;
                let attached = h < layer + NEAR && (style.hug || n.y > -0.1);
                if attached && (project || flow.dot(n) < 0.0) {
                    let along = flow - n * flow.dot(n);
                    flow = along
                        .try_normalize()
                        .or_else(|| (d - n * d.dot(n)).try_normalize())
                        .unwrap_or(flow);
                    let lift = (0.5 * (layer - h) / ds).clamp(-0.3, 1.0);
                    flow = (flow + n * lift).normalize_or(flow);
                } else if h <= layer {
                    let into = flow.dot(n);
                    if into < 0.0 {
                        flow = (flow - n * into).normalize_or(n);
                    }
                }
            }
            let alpha = dmath::exp((-s / style.rise) as f64) as f32;
            let target = (up * alpha + flow * (1.0 - alpha)).normalize_or(flow);
            d = (d * STIFFNESS + target * (1.0 - STIFFNESS)).normalize_or(target);
            let Some((q, q_probe)) = self.place(p, p + d * ds, ds) else {
                break;
            };
            d = (q - p).normalize_or(d);
            pts.push(q);
            p = q;
            probe = q_probe;
            s += ds;
        }
        pts
    }

    /// Moves a proposed next point out of the skin and the face while keeping it `ds` from
    /// `prev`; returns it with its skin probe, or `None` when no such spot is found.
    fn place(&self, prev: Vec3, proposed: Vec3, ds: f32) -> Option<(Vec3, Probe)> {
        let mut q = proposed;
        for _ in 0..4 {
            let r = self.resolve(q);
            if r.clear && !r.moved {
                return Some((r.point, r.probe));
            }
            q = prev + (r.point - prev).try_normalize()? * ds;
        }
        None
    }

    /// Pushes `p` out of the skin (to [`MARGIN`], when it is more than [`CLEAR_TOLERANCE`]
    /// below it) and out of the face keep-out.
    fn resolve(&self, p: Vec3) -> Resolved {
        let mut q = p;
        let mut moved = false;
        for _ in 0..6 {
            let probe = self.skin.probe_vertex(q);
            let mut step = false;
            if let Some((h, n, open_edge)) = probe {
                if h < MARGIN - CLEAR_TOLERANCE {
                    if open_edge {
                        // Past the edge of the skin (a cut neck or arm) there is no telling
                        // where the body is; the strand ends here.
                        break;
                    }
                    q += n * (MARGIN - h);
                    step = true;
                }
            }
            if self.frame.in_face(q) {
                q = self.frame.out_of_face(q);
                step = true;
            }
            if !step {
                return Resolved {
                    point: q,
                    moved,
                    clear: true,
                    probe: probe.map(|(h, n, _)| (h, n)),
                };
            }
            moved = true;
        }
        Resolved {
            point: q,
            moved,
            clear: false,
            probe: None,
        }
    }

    /// Final collision pass after clumping and curl moved the points; the strand ends at the
    /// first point that cannot be placed.
    fn settle(&self, pts: &mut Vec<Vec3>) {
        for j in 1..pts.len() {
            let r = self.resolve(pts[j]);
            if !r.clear {
                pts.truncate(j);
                return;
            }
            pts[j] = r.point;
        }
    }

    /// Grows every strand long, then cuts them all at one height (with a few mm of jitter)
    /// chosen so the mean centreline length is `mean_length`, and resamples them.
    fn grow_bob(&self, plans: &[StrandPlan], mean_length: f32) -> Vec<(Vec<Vec3>, f32)> {
        const GROW_STEP: f32 = 0.012;
        const MIN_LEN: f32 = 0.015;
        let grow_len = (2.2 * mean_length).min(0.6);
        let steps = (grow_len / GROW_STEP).ceil() as usize;
        // Most of a long-grown strand is cut off; a subset tells roughly where the cut will be,
        // so the full set only grows a little past it.
        let stride = (plans.len() / 500).max(1);
        let subset: Vec<Vec<Vec3>> = plans
            .iter()
            .step_by(stride)
            .map(|p| self.grow_path(p, steps, GROW_STEP, |_, _| Steer::Comb))
            .collect();
        let rough_cut = cut_height(&subset, &vec![0.0; subset.len()], mean_length, MIN_LEN);
        let stop_below = rough_cut - 0.03;
        let long: Vec<Vec<Vec3>> = plans
            .iter()
            .map(|p| {
                self.grow_path(p, steps, GROW_STEP, |q, _| {
                    if q.y < stop_below {
                        Steer::Stop
                    } else {
                        Steer::Comb
                    }
                })
            })
            .collect();
        let jitter: Vec<f32> = (0..plans.len())
            .map(|i| {
                let mut rng = Rng::new(self.seed, STREAM_STRAND, (i as u64) | (1 << 40));
                rng.range(-0.004, 0.004)
            })
            .collect();
        let cut = cut_height(&long, &jitter, mean_length, MIN_LEN);
        long.iter()
            .zip(&jitter)
            .zip(plans)
            .map(|((pts, j), plan)| {
                let arc = arc_to_height(pts, cut + j).max(MIN_LEN);
                let segments = ((arc * self.curl.stretch() / self.style.segment).ceil() as usize)
                    .clamp(2, self.style.max_segments)
                    .min(plan.segments.max(2));
                (resample(pts, arc, segments), 0.0)
            })
            .collect()
    }

    /// A ponytail strand: over the scalp to its place in the tie, then down the tail.
    /// Returns the points and the arc length at the tie, where the tail (and its curl) starts.
    fn grow_ponytail(
        &self,
        plan: &StrandPlan,
        guide: &StrandPlan,
        tail: &Tail,
    ) -> (Vec<Vec3>, f32) {
        let ds = plan.length / plan.segments as f32;
        let target = tail.point(0.0, plan.slot, guide.slot, 0.0, self.clumping);
        let mut pts = self.grow_path(plan, plan.segments, ds, |p, s| {
            let to = target - p;
            let dist = to.length();
            if dist <= ds || s > 0.85 * plan.length {
                Steer::Stop
            } else {
                // Along the scalp towards the tie; within 3 cm, straight at it (it stands off
                // the skin by the tie's thickness).
                Steer::Towards(to / dist, dist >= 0.03)
            }
        });
        let head_arc: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
        let Some(&last) = pts.last() else {
            return (pts, 0.0);
        };
        if last.distance(target) > 2.0 * ds {
            // Never reached the tie: the strand ends on the scalp, shortened.
            return (pts, head_arc);
        }
        let remaining = plan.length - head_arc;
        let steps = (remaining / ds).floor() as usize;
        let tail_len = remaining.max(ds);
        let mut prev = last;
        for j in 1..=steps {
            let sigma = j as f32 * ds;
            let q = tail.point(
                sigma,
                plan.slot,
                guide.slot,
                sigma / tail_len,
                self.clumping,
            );
            let step = q.distance(prev).max(0.25 * ds);
            let Some((q, _)) = self.place(prev, q, step) else {
                break;
            };
            pts.push(q);
            prev = q;
        }
        (pts, head_arc)
    }
}

/// Height above the nearest skin vertex's tangent plane and that vertex's normal; `None` in
/// free space.
type Probe = Option<(f32, Vec3)>;

/// Outcome of [`Grower::resolve`].
struct Resolved {
    point: Vec3,
    /// The point had to be moved.
    moved: bool,
    /// The point is outside the skin and the face.
    clear: bool,
    /// Skin probe at `point` when `clear`.
    probe: Probe,
}

/// What drives a growth step.
#[derive(Clone, Copy, Debug)]
enum Steer {
    /// The strand's comb direction blended with gravity, along the scalp.
    Comb,
    /// This direction; along the scalp when the flag is set.
    Towards(Vec3, bool),
    /// The strand ends here.
    Stop,
}

/// The ponytail: a tie point behind and above the ears, and the axis the tail hangs along.
struct Tail {
    /// Axis points every [`Tail::STEP`] from the tie.
    axis: Vec<Vec3>,
    radius: f32,
}

impl Tail {
    const STEP: f32 = 0.002;
    const MAX_LEN: f32 = 1.2;

    fn new(skin: &Skin, frame: &HeadFrame) -> Tail {
        let k = frame.k;
        let tie_y = frame.ear_y + 0.035 * k;
        // The hindmost skin on the midline at tie height; the tie sits on the hair there.
        let back = skin
            .grid
            .items
            .iter()
            .map(|&i| (skin.positions[i as usize], skin.normals[i as usize]))
            .filter(|(p, _)| (p.x - frame.mid_x).abs() < 0.012 && (p.y - tie_y).abs() < 0.012)
            .min_by(|a, b| a.0.z.total_cmp(&b.0.z));
        let tie = match back {
            Some((p, n)) => p + (n * 0.6 + Vec3::NEG_Z * 0.4).normalize_or(Vec3::NEG_Z) * 0.014 * k,
            None => Vec3::new(frame.mid_x, tie_y, frame.crown.z - 0.1 * k),
        };
        let steps = (Self::MAX_LEN / Self::STEP) as usize;
        let mut axis = Vec::with_capacity(steps + 1);
        let mut p = tie;
        let mut d = Vec3::new(0.0, -0.45, -0.55).normalize_or(DOWN);
        axis.push(p);
        for _ in 0..steps {
            // Bends from back-and-down to straight down over the first ~8 cm.
            d = (d + DOWN * 0.05).normalize_or(DOWN);
            p += d * Self::STEP;
            axis.push(p);
        }
        Tail {
            axis,
            radius: 0.009 * k,
        }
    }

    /// Place in the tie's cross-section (unit disc) at radius `r` for a strand rooted at
    /// `root`: on the side of the tie the root lies.
    fn slot(&self, root: Vec3, r: f32) -> [f32; 2] {
        let (b1, b2) = self.frame(0);
        let to_root = root - self.axis[0];
        let dir = Vec2::new(to_root.dot(b1), to_root.dot(b2)).normalize_or(Vec2::X);
        (dir * r).to_array()
    }

    /// Cross-section axes at axis sample `i`.
    fn frame(&self, i: usize) -> (Vec3, Vec3) {
        let i = i.min(self.axis.len() - 2);
        let tangent = (self.axis[i + 1] - self.axis[i]).normalize_or(DOWN);
        let b1 = Vec3::X;
        (b1, tangent.cross(b1).normalize_or(Vec3::Z))
    }

    /// Point at `sigma` along the tail for a strand at `slot` of the cross-section, pulled
    /// towards its guide's slot by `clumping` as `t` (0 at the tie, 1 at the tip) grows.
    fn point(&self, sigma: f32, slot: [f32; 2], guide: [f32; 2], t: f32, clumping: f32) -> Vec3 {
        let x = (sigma / Self::STEP).max(0.0);
        let i = (x.floor() as usize).min(self.axis.len() - 2);
        let f = (x - i as f32).min(1.0);
        let c = self.axis[i].lerp(self.axis[i + 1], f);
        let (b1, b2) = self.frame(i);
        let pull = clumping * 0.9 * smoothstep(0.0, 1.0, t);
        let sx = slot[0] + (guide[0] - slot[0]) * pull;
        let sy = slot[1] + (guide[1] - slot[1]) * pull;
        let r = self.radius * (1.0 + 1.2 * smoothstep(0.0, 0.12, sigma));
        c + (b1 * sx + b2 * sy) * r
    }
}

/// Index of each strand's guide: the nearest of the first `len / GUIDE_EVERY` roots (the roots
/// are in random order, so those are a random subset); guides are their own guide.
fn assign_guides(roots: &[Root]) -> Vec<usize> {
    let n_guides = roots.len().div_ceil(GUIDE_EVERY).max(1).min(roots.len());
    if n_guides == 0 {
        return Vec::new();
    }
    let positions: Vec<Vec3> = roots.iter().map(|r| r.pos).collect();
    let ids: Vec<u32> = (0..n_guides as u32).collect();
    let grid = PointGrid::new(&positions, &ids, 0.01, 0.0);
    (0..roots.len())
        .map(|i| {
            if i < n_guides {
                i
            } else {
                grid.nearest(positions[i], f32::INFINITY)
                    .map_or(0, |(g, _)| g as usize)
            }
        })
        .collect()
}

/// Pulls each strand towards its guide at the same fraction of its length, increasingly from
/// root (free) to tip (`0.9 × clumping` of the way).
fn clump(lines: &[(Vec<Vec3>, f32)], guides: &[usize], clumping: f32) -> Vec<(Vec<Vec3>, f32)> {
    lines
        .iter()
        .enumerate()
        .map(|(i, (pts, start))| {
            let g = guides.get(i).copied().unwrap_or(i);
            if g == i || pts.len() < 2 {
                return (pts.clone(), *start);
            }
            let guide = &lines[g].0;
            let arcs = cumulative_arc(pts);
            let total = arcs.last().copied().unwrap_or(0.0).max(1e-9);
            let out = pts
                .iter()
                .zip(&arcs)
                .map(|(p, a)| {
                    let t = a / total;
                    let w = 0.9 * clumping * smoothstep(0.0, 1.0, t);
                    // A capped pull cannot carry a point through the head or neck to a guide
                    // on the other side of it (the collision pass only sees skin within
                    // PROBE_RANGE).
                    *p + ((point_at_fraction(guide, t) - *p) * w).clamp_length_max(MAX_CLUMP_PULL)
                })
                .collect();
            (out, *start)
        })
        .collect()
}

fn cumulative_arc(pts: &[Vec3]) -> Vec<f32> {
    let mut acc = 0.0;
    let mut out = Vec::with_capacity(pts.len());
    for (j, p) in pts.iter().enumerate() {
        if j > 0 {
            acc += p.distance(pts[j - 1]);
        }
        out.push(acc);
    }
    out
}

/// Point at fraction `t` of a polyline's arc length.
fn point_at_fraction(pts: &[Vec3], t: f32) -> Vec3 {
    let total: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
    point_at_arc(pts, t.clamp(0.0, 1.0) * total)
}

fn point_at_arc(pts: &[Vec3], arc: f32) -> Vec3 {
    let mut left = arc;
    for w in pts.windows(2) {
        let l = w[0].distance(w[1]);
        if left <= l {
            return if l > 0.0 {
                w[0].lerp(w[1], left / l)
            } else {
                w[0]
            };
        }
        left -= l;
    }
    pts.last().copied().unwrap_or(Vec3::ZERO)
}

/// The first `arc` metres of a polyline as `segments` equal pieces.
fn resample(pts: &[Vec3], arc: f32, segments: usize) -> Vec<Vec3> {
    (0..=segments)
        .map(|j| point_at_arc(pts, arc * j as f32 / segments as f32))
        .collect()
}

/// Height at which cutting every strand (each `jitter` higher) leaves a mean length of
/// `mean_length`, strands shorter than `min_len` kept at that length.
fn cut_height(lines: &[Vec<Vec3>], jitter: &[f32], mean_length: f32, min_len: f32) -> f32 {
    let mean_at = |y: f32| -> f32 {
        let sum: f64 = lines
            .iter()
            .zip(jitter)
            .map(|(pts, j)| arc_to_height(pts, y + j).max(min_len) as f64)
            .sum();
        (sum / lines.len().max(1) as f64) as f32
    };
    let (lowest, highest) = lines
        .iter()
        .flatten()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.y), hi.max(p.y))
        });
    if !(lowest.is_finite() && highest.is_finite()) {
        return 0.0;
    }
    let (mut lo, mut hi) = (lowest - 0.01, highest + 0.01);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if mean_at(mid) > mean_length {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Arc length at which a polyline first goes below height `y`: 0 when it starts below, its
/// whole length when it never does.
fn arc_to_height(pts: &[Vec3], y: f32) -> f32 {
    let Some(first) = pts.first() else {
        return 0.0;
    };
    if first.y < y {
        return 0.0;
    }
    let mut arc = 0.0;
    for w in pts.windows(2) {
        let l = w[0].distance(w[1]);
        if w[1].y < y {
            let f = (w[0].y - y) / (w[0].y - w[1].y);
            return arc + l * f;
        }
        arc += l;
    }
    arc
}

/// Helix around a centreline: radius `amplitude` ramping in over 1.5 cm after arc length
/// `start`, one turn per `period` of centreline. The frame is parallel-transported from
/// `reference` so neighbouring strands with the same reference curl alike.
fn add_curl(
    line: &[Vec3],
    start: f32,
    amplitude: f32,
    period: f32,
    phase: f32,
    reference: Vec3,
) -> Vec<Vec3> {
    let n = line.len();
    let arcs = cumulative_arc(line);
    let tangent =
        |j: usize| (line[(j + 1).min(n - 1)] - line[j.saturating_sub(1)]).normalize_or(DOWN);
    let t0 = tangent(0);
    let mut b1 = (reference - t0 * reference.dot(t0))
        .try_normalize()
        .unwrap_or_else(|| any_perpendicular(t0));
    let mut out = Vec::with_capacity(n);
    for j in 0..n {
        let t = tangent(j);
        b1 = (b1 - t * b1.dot(t))
            .try_normalize()
            .unwrap_or_else(|| any_perpendicular(t));
        let b2 = t.cross(b1);
        let s = arcs[j];
        let a = amplitude * smoothstep(start, start + 0.015, s);
        let theta = phase as f64 + std::f64::consts::TAU * ((s - start).max(0.0) / period) as f64;
        let (sin, cos) = dmath::sin_cos(theta);
        out.push(line[j] + (b1 * cos as f32 + b2 * sin as f32) * a);
    }
    out
}

fn any_perpendicular(n: Vec3) -> Vec3 {
    let r = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    (r - n * r.dot(n)).normalize_or(Vec3::Z)
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// SplitMix64 (Steele et al. 2014): small, fast and the same everywhere.
struct Rng(u64);

const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

fn mix(z: u64) -> u64 {
    let z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    fn new(seed: u64, stream: u64, index: u64) -> Rng {
        let key =
            mix(seed
                ^ mix(stream.wrapping_mul(GOLDEN_GAMMA) ^ mix(index.wrapping_add(GOLDEN_GAMMA))));
        Rng(key)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        mix(self.0)
    }

    /// Uniform in [0, 1).
    fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / 16_777_216.0)
    }

    /// Uniform in [0, 1).
    fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }

    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }
}

/// Uniform grid over a subset of points for nearest-point queries. Each cell also knows how
/// many rings of cells around it are empty, so queries far from every point stay cheap.
struct PointGrid {
    origin: Vec3,
    cell: f32,
    dims: [usize; 3],
    /// Prefix sums into `items`, one per cell plus one.
    starts: Vec<u32>,
    items: Vec<u32>,
    /// The points of `items`, in the same (cell) order, so a query reads memory in sequence.
    item_points: Vec<Vec3>,
    /// Chebyshev distance, in cells, to the nearest non-empty cell (capped at 255).
    empty_rings: Vec<u8>,
}

impl PointGrid {
    /// Grid over `points[ids]` (all finite), padded by `pad` on every side.
    fn new(points: &[Vec3], ids: &[u32], cell: f32, pad: f32) -> PointGrid {
        const MAX_DIM: f32 = 160.0;
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for &i in ids {
            lo = lo.min(points[i as usize]);
            hi = hi.max(points[i as usize]);
        }
        if ids.is_empty() {
            lo = Vec3::ZERO;
            hi = Vec3::ZERO;
        }
        let pad = if pad.is_finite() { pad } else { 0.0 };
        let lo = lo - Vec3::splat(pad);
        let extent = (hi + Vec3::splat(pad)) - lo;
        // Bounded memory for huge or degenerate inputs: the cell grows instead.
        let cell = cell.max(extent.max_element() / MAX_DIM).max(1e-6);
        let dims = [extent.x, extent.y, extent.z].map(|e| (e / cell).floor() as usize + 1);
        let n_cells = dims[0] * dims[1] * dims[2];
        let cell_of = |p: Vec3| -> usize {
            let c = ((p - lo) / cell).floor();
            let ix = (c.x.max(0.0) as usize).min(dims[0] - 1);
            let iy = (c.y.max(0.0) as usize).min(dims[1] - 1);
            let iz = (c.z.max(0.0) as usize).min(dims[2] - 1);
            (iz * dims[1] + iy) * dims[0] + ix
        };
        let mut counts = vec![0u32; n_cells + 1];
        for &i in ids {
            counts[cell_of(points[i as usize]) + 1] += 1;
        }
        for c in 0..n_cells {
            counts[c + 1] += counts[c];
        }
        let starts = counts.clone();
        let mut fill = counts;
        let mut items = vec![0u32; ids.len()];
        for &i in ids {
            let c = cell_of(points[i as usize]);
            items[fill[c] as usize] = i;
            fill[c] += 1;
        }
        // Multi-source breadth-first search over the 26-neighbourhood gives the Chebyshev
        // distance to the nearest occupied cell.
        let mut empty_rings = vec![u8::MAX; n_cells];
        let mut queue = std::collections::VecDeque::new();
        for c in 0..n_cells {
            if starts[c + 1] > starts[c] {
                empty_rings[c] = 0;
                queue.push_back(c);
            }
        }
        while let Some(c) = queue.pop_front() {
            let d = empty_rings[c];
            if d == u8::MAX - 1 {
                continue;
            }
            let (ix, iy, iz) = (
                c % dims[0],
                (c / dims[0]) % dims[1],
                c / (dims[0] * dims[1]),
            );
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (x, y, z) = (ix as i64 + dx, iy as i64 + dy, iz as i64 + dz);
                        if x < 0 || y < 0 || z < 0 {
                            continue;
                        }
                        let (x, y, z) = (x as usize, y as usize, z as usize);
                        if x >= dims[0] || y >= dims[1] || z >= dims[2] {
                            continue;
                        }
                        let nc = (z * dims[1] + y) * dims[0] + x;
                        if empty_rings[nc] > d + 1 {
                            empty_rings[nc] = d + 1;
                            queue.push_back(nc);
                        }
                    }
                }
            }
        }
        let item_points = items.iter().map(|&i| points[i as usize]).collect();
        PointGrid {
            origin: lo,
            cell,
            dims,
            starts,
            items,
            item_points,
            empty_rings,
        }
    }

    /// Nearest indexed point to `p` within `max_dist`, with its squared distance.
    fn nearest(&self, p: Vec3, max_dist: f32) -> Option<(u32, f32)> {
        if self.items.is_empty() || !p.is_finite() {
            return None;
        }
        let c = (p - self.origin) / self.cell;
        let f = c - c.floor();
        let c = c.floor();
        let dims = self.dims.map(|d| d as i64);
        let (cx, cy, cz) = (c.x as i64, c.y as i64, c.z as i64);
        // Outside the grid: start from the nearest cell and skip the rings that are surely
        // empty or beyond `max_dist`.
        let clamp = |v: i64, d: i64| v.clamp(0, d - 1);
        let (qx, qy, qz) = (clamp(cx, dims[0]), clamp(cy, dims[1]), clamp(cz, dims[2]));
        let outside = (cx - qx).abs().max((cy - qy).abs()).max((cz - qz).abs());
        let q_cell = ((qz * dims[1] + qy) * dims[0] + qx) as usize;
        let first_ring = (self.empty_rings[q_cell] as i64).max(outside.saturating_sub(1));
        // Points in ring r are at least r - 1 cells plus p's distance to its own cell's
        // nearest face away.
        let inset = if outside == 0 {
            f.min(Vec3::ONE - f).min_element().max(0.0)
        } else {
            0.0
        };
        let mut best: Option<(u32, f32)> = None;
        let mut best_d2 = if max_dist.is_finite() {
            max_dist * max_dist
        } else {
            f32::INFINITY
        };
        let max_ring = dims[0].max(dims[1]).max(dims[2]) + outside + 1;
        let mut r = first_ring;
        while r <= max_ring {
            if r > 0 {
                let lower = ((r - 1) as f32 + inset) * self.cell;
                if lower * lower > best_d2 {
                    break;
                }
            }
            for dz in -r..=r {
                let z = cz + dz;
                if z < 0 || z >= dims[2] {
                    continue;
                }
                for dy in -r..=r {
                    let y = cy + dy;
                    if y < 0 || y >= dims[1] {
                        continue;
                    }
                    let on_face = dz.abs() == r || dy.abs() == r;
                    let step = if on_face { 1 } else { (2 * r).max(1) };
                    let mut dx = -r;
                    while dx <= r {
                        let x = cx + dx;
                        dx += step;
                        if x < 0 || x >= dims[0] {
                            continue;
                        }
                        let cell = ((z * dims[1] + y) * dims[0] + x) as usize;
                        let (a, b) = (self.starts[cell] as usize, self.starts[cell + 1] as usize);
                        if b == a || self.cell_distance_sq(p, x, y, z) > best_d2 {
                            continue;
                        }
                        for (k, q) in self.item_points[a..b].iter().enumerate() {
                            let d2 = q.distance_squared(p);
                            if d2 > best_d2 {
                                continue;
                            }
                            let i = self.items[a + k];
                            // Ties go to the lower index, whatever the scan order.
                            let better = match best {
                                None => true,
                                Some((bi, bd)) => d2 < bd || i < bi,
                            };
                            if better {
                                best = Some((i, d2));
                                best_d2 = d2;
                            }
                        }
                    }
                }
            }
            r += 1;
        }
        best
    }

    fn cell_distance_sq(&self, p: Vec3, x: i64, y: i64, z: i64) -> f32 {
        let lo = self.origin + Vec3::new(x as f32, y as f32, z as f32) * self.cell;
        let hi = lo + Vec3::splat(self.cell);
        let d = (lo - p).max(p - hi).max(Vec3::ZERO);
        d.length_squared()
    }
}

/// Transcendental functions from basic IEEE operations only, so strands are bit-identical
/// whatever libm the platform has. Accurate to a few ulp over the ranges used here.
mod dmath {
    use std::f64::consts::{FRAC_PI_2, LN_2, PI, SQRT_2};

    pub fn exp(x: f64) -> f64 {
        if x.is_nan() {
            return x;
        }
        // ln 2 as a head with trailing zero bits (so k × head is exact) and a tail (fdlibm).
        const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
        const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);
        let x = x.clamp(-700.0, 700.0);
        let k = (x / LN_2).round();
        let r = (x - k * LN2_HI) - k * LN2_LO;
        let (mut term, mut sum) = (1.0, 1.0);
        for i in 1..=13 {
            term *= r / i as f64;
            sum += term;
        }
        sum * f64::from_bits(((k as i64 + 1023) as u64) << 52)
    }

    /// Natural logarithm of a positive normal number.
    pub fn ln(x: f64) -> f64 {
        if x.is_nan() || x <= 0.0 {
            return f64::NAN;
        }
        let x = x.max(f64::MIN_POSITIVE);
        let bits = x.to_bits();
        let mut e = ((bits >> 52) & 0x7ff) as i64 - 1023;
        let mut m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
        if m > SQRT_2 {
            m *= 0.5;
            e += 1;
        }
        // ln m = 2 atanh(s), |s| <= 0.172
        let s = (m - 1.0) / (m + 1.0);
        let s2 = s * s;
        let (mut term, mut sum) = (s, 0.0);
        for i in 0..14 {
            sum += term / (2 * i + 1) as f64;
            term *= s2;
        }
        2.0 * sum + e as f64 * LN_2
    }

    pub fn sin_cos(x: f64) -> (f64, f64) {
        // π/2 split the same way.
        const PIO2_HI: f64 = f64::from_bits(0x3FF9_21FB_5440_0000);
        const PIO2_LO: f64 = f64::from_bits(0x3DD0_B461_1A62_6331);
        let k = (x / FRAC_PI_2).round();
        let r = (x - k * PIO2_HI) - k * PIO2_LO;
        let r2 = r * r;
        let (mut s, mut c) = (0.0, 0.0);
        let (mut ts, mut tc) = (r, 1.0);
        for i in 0..10 {
            s += ts;
            c += tc;
            let i = i as f64;
            ts *= -r2 / ((2.0 * i + 2.0) * (2.0 * i + 3.0));
            tc *= -r2 / ((2.0 * i + 1.0) * (2.0 * i + 2.0));
        }
        match (k as i64).rem_euclid(4) {
            0 => (s, c),
            1 => (c, -s),
            2 => (-s, -c),
            _ => (-c, s),
        }
    }

    pub fn atan(t: f64) -> f64 {
        if t.is_nan() {
            return t;
        }
        let a = t.abs();
        let (a, inverted) = if a > 1.0 { (1.0 / a, true) } else { (a, false) };
        // Two argument halvings, atan(a) = 2 atan(a / (1 + sqrt(1 + a²))), bring |a| under
        // tan(π/16) where the series converges fast.
        let b = a / (1.0 + (1.0 + a * a).sqrt());
        let c = b / (1.0 + (1.0 + b * b).sqrt());
        let c2 = c * c;
        let (mut term, mut sum) = (c, 0.0);
        for i in 0..12 {
            let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
            sum += sign * term / (2 * i + 1) as f64;
            term *= c2;
        }
        let r = 4.0 * sum;
        let r = if inverted { FRAC_PI_2 - r } else { r };
        r.copysign(t)
    }

    pub fn atan2(y: f64, x: f64) -> f64 {
        if x > 0.0 {
            atan(y / x)
        } else if x < 0.0 {
            if y >= 0.0 {
                atan(y / x) + PI
            } else {
                atan(y / x) - PI
            }
        } else if y > 0.0 {
            FRAC_PI_2
        } else if y < 0.0 {
            -FRAC_PI_2
        } else {
            0.0
        }
    }

    #[cfg(test)]
    mod tests {
        #[test]
        fn matches_std_within_a_few_ulp() {
            for i in -400..=400 {
                let x = i as f64 * 0.037;
                assert!((super::exp(x) / x.exp() - 1.0).abs() < 1e-14, "exp {x}");
                let (s, c) = super::sin_cos(x * 7.0);
                assert!((s - (x * 7.0).sin()).abs() < 1e-14, "sin {x}");
                assert!((c - (x * 7.0).cos()).abs() < 1e-14, "cos {x}");
                assert!(
                    (super::atan(x * 3.0) - (x * 3.0).atan()).abs() < 1e-14,
                    "atan {x}"
                );
                let y = (i as f64 * 0.011).abs() + 1e-3;
                assert!((super::ln(y) - y.ln()).abs() < 1e-14, "ln {y}");
                for (yy, xx) in [(x, 1.0), (x, -1.0), (1.0, x), (-1.0, x)] {
                    assert!((super::atan2(yy, xx) - yy.atan2(xx)).abs() < 1e-14);
                }
            }
        }
    }
}
