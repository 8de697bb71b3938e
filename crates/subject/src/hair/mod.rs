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
//! index), each strand, brow hair and lash is a pure function of its own stream and the
//! read-only skin (grown on every core with rayon and collected in index order, so the thread
//! count never shows; the one reduction, the bob's mean length, runs in a fixed order on one
//! thread), and the few transcendental
//! functions (exp, ln, sin/cos, atan2) come from the pure-Rust `libm` crate rather than the
//! platform's C library, so the output is bit-identical on every platform.
//!
//! **Layout.** [`Strands`] (`strands.rs`; as the renderer's fibres in `fibres.rs`, as the old
//! camera-facing ribbons in `ribbons.rs`) is the output;
//! [`grow_hair`] (`growth.rs`) grows a style from `styles.rs` on the scalp of `scalp.rs`, with
//! the bob cut in `bob.rs` and the ponytail's tie in `ponytail.rs`, and shapes the strands with
//! `clump.rs` and `curl.rs`; [`grow_eyebrows`] is in `eyebrows.rs`, [`grow_eyelashes`] (on
//! the lid margins of [`crate::eyelids`]) in `eyelashes.rs` and [`hair_albedo`] in
//! `albedo.rs`. `polyline.rs`, `rng.rs` and `grid.rs` are the shared helpers.
//!
//! [`Landmarks`]: crate::Landmarks

use glam::Vec3;

mod albedo;
mod bob;
mod clump;
mod curl;
mod eyebrows;
mod eyelashes;
mod fibres;
mod grid;
mod growth;
mod polyline;
mod ponytail;
mod ribbons;
mod rng;
mod scalp;
mod strands;
mod styles;

pub use albedo::hair_albedo;
pub use eyebrows::grow_eyebrows;
pub use eyelashes::grow_eyelashes;
pub use fibres::hair_fibre_material;
pub use growth::grow_hair;
pub use strands::Strands;
pub use styles::HAIR_STYLES;

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

// Random streams; fixed numbers so that adding a stream never changes existing output.
const STREAM_ROOTS: u64 = 1;
const STREAM_STRAND: u64 = 2;
const STREAM_HEAD: u64 = 3;
const STREAM_BROW_ROOTS: u64 = 4;
const STREAM_BROW_STRAND: u64 = 5;
const STREAM_LASH: u64 = 6;
