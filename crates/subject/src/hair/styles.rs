//! The hair styles and their per-style templates.

/// The hair styles [`grow_hair`](super::grow_hair) knows, in the order of
/// `lightfarm_scene::expand::HAIR_RANGES`.
pub const HAIR_STYLES: [&str; 6] = ["buzz", "short", "bob", "long", "curly", "ponytail"];

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Kind {
    Buzz,
    Flow,
    Bob,
    Ponytail,
}

/// Per-style template; see the module documentation for the budget behind the numbers.
pub(super) struct Style {
    pub(super) name: &'static str,
    pub(super) kind: Kind,
    /// Strands at density 1.
    pub(super) strands: u32,
    pub(super) max_segments: usize,
    /// Target segment length, metres.
    pub(super) segment: f32,
    pub(super) root_width: f32,
    /// Largest height of a strand's layer above the scalp (volume), metres.
    pub(super) lift: f32,
    /// Arc length over which a strand turns from the skin normal into its comb direction.
    pub(super) rise: f32,
    /// Weight of gravity against the comb direction once the strand is a few cm long.
    pub(super) gravity: f32,
    /// Styled hair follows the scalp even where it faces down (no hanging).
    pub(super) hug: bool,
    pub(super) parted: bool,
    /// Relative spread of strand lengths (uniform ±).
    pub(super) length_jitter: f32,
}

pub(super) const STYLES: [Style; 6] = [
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
