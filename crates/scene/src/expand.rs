//! Deterministic expansion of sample `i` of a dataset into everything needed to render it.
//!
//! [`expand`] is a pure function of the [`ResolvedSpec`] and the index: every random decision
//! draws from its own counter-based stream `SampleRng::new(seed, index, STREAM)` (see `rng`), so
//! a coordinator can expand samples in any order, on any machine, and a worker re-expanding a
//! sample gets the same bytes. Adding a decision later means adding a stream, which leaves the
//! existing decisions of old datasets unchanged.
//!
//! # Distributions (Yeh et al. 2022, section 3, unless noted)
//!
//! - **Identity and split.** The identity is uniform over all selected identities (sorted by
//!   name), then the head asset uniform among that identity's heads. The sample's split is the
//!   split of its identity: `"test"` when the identity is held out, else `"train"`. So held-out
//!   identities never appear in training samples, test samples use only held-out identities, and
//!   the expected share of test samples is (held-out identities) / (all identities).
//! - **Expression.** With `subject.expression_probability` one of six kinds, uniformly: `smile`
//!   (`mouthSmileLeft/Right`), `jaw_open` (`jawOpen`), `blink` (`eyeBlinkLeft/Right`),
//!   `surprise` (`browInnerUp`, `eyeWideLeft/Right`, `jawOpen`), `frown`
//!   (`browDownLeft/Right`, `mouthFrownLeft/Right`) — all weights one intensity drawn in
//!   [0.5, 1] so the expression is clearly visible — or `random`: 3–6 distinct names of the 52
//!   ARKit blendshapes, each weight uniform in [0, 1]. Otherwise `neutral` (no weights).
//! - **Hair.** Style uniform over `subject.hair_styles`; melanin and redness uniform in their
//!   ranges (paper); the strand parameters uniform in the per-style ranges of [`HAIR_RANGES`].
//! - **Garment** with `subject.garment_probability`: asset uniform; linear-RGB colour with each
//!   channel uniform in [`GARMENT_ALBEDO`]; roughness uniform in `subject.garment_roughness`.
//! - **Glasses** with probability 0.2, **headset** with 0.05 (paper), asset uniform.
//! - **Camera.** Yaw and pitch uniform in degrees within their ranges (the paper gives the
//!   ranges, not the density; uniform in angle is the plain reading), fixed radius and field of
//!   view, subject offset uniform in the cube `[-jitter_m, jitter_m]^3`.
//! - **Lighting.** Two different HDRIs, the ordered pair uniform over all ordered pairs of
//!   distinct selected HDRIs; each with its own rotation uniform in `lighting.rotation_deg` and a
//!   horizontal flip with `lighting.flip_probability`.
//! - **Render seed.** The top 32 bits of the render stream: the renderer's per-pixel random
//!   numbers are keyed by it, so a re-render reproduces the image.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::catalog::{Asset, Catalog};
use crate::error::SceneError;
use crate::identity::{identity_name, sample_identity, SyntheticIdentity, SYNTHETIC};
use crate::rng::SampleRng;
use crate::spec::{AssetRef, ResolvedSpec};

// One stream per decision; the numbers are part of the dataset format (changing one changes
// every existing dataset), so they are fixed constants, never derived from declaration order.
const STREAM_IDENTITY: u64 = 1;
const STREAM_EXPRESSION: u64 = 2;
const STREAM_HAIR: u64 = 3;
const STREAM_GARMENT: u64 = 4;
const STREAM_GLASSES: u64 = 5;
const STREAM_HEADSET: u64 = 6;
const STREAM_CAMERA: u64 = 7;
const STREAM_LIGHTING: u64 = 8;
const STREAM_RENDER: u64 = 9;
const STREAM_HAIR_FIBRE: u64 = 10;

/// The 52 ARKit face blendshape names (Apple's `ARFaceAnchor.BlendShapeLocation`), the morph
/// target names of the built-in heads.
pub const ARKIT_BLENDSHAPES: [&str; 52] = [
    "eyeBlinkLeft",
    "eyeLookDownLeft",
    "eyeLookInLeft",
    "eyeLookOutLeft",
    "eyeLookUpLeft",
    "eyeSquintLeft",
    "eyeWideLeft",
    "eyeBlinkRight",
    "eyeLookDownRight",
    "eyeLookInRight",
    "eyeLookOutRight",
    "eyeLookUpRight",
    "eyeSquintRight",
    "eyeWideRight",
    "jawForward",
    "jawLeft",
    "jawRight",
    "jawOpen",
    "mouthClose",
    "mouthFunnel",
    "mouthPucker",
    "mouthLeft",
    "mouthRight",
    "mouthSmileLeft",
    "mouthSmileRight",
    "mouthFrownLeft",
    "mouthFrownRight",
    "mouthDimpleLeft",
    "mouthDimpleRight",
    "mouthStretchLeft",
    "mouthStretchRight",
    "mouthRollLower",
    "mouthRollUpper",
    "mouthShrugLower",
    "mouthShrugUpper",
    "mouthPressLeft",
    "mouthPressRight",
    "mouthLowerDownLeft",
    "mouthLowerDownRight",
    "mouthUpperUpLeft",
    "mouthUpperUpRight",
    "browDownLeft",
    "browDownRight",
    "browInnerUp",
    "browOuterUpLeft",
    "browOuterUpRight",
    "cheekPuff",
    "cheekSquintLeft",
    "cheekSquintRight",
    "noseSneerLeft",
    "noseSneerRight",
    "tongueOut",
];

/// The expression kinds other than `neutral`, each with the blendshapes it drives (empty for
/// `random`, which draws its own).
const EXPRESSIONS: [(&str, &[&str]); 6] = [
    ("smile", &["mouthSmileLeft", "mouthSmileRight"]),
    ("jaw_open", &["jawOpen"]),
    ("blink", &["eyeBlinkLeft", "eyeBlinkRight"]),
    (
        "surprise",
        &["browInnerUp", "eyeWideLeft", "eyeWideRight", "jawOpen"],
    ),
    (
        "frown",
        &[
            "browDownLeft",
            "browDownRight",
            "mouthFrownLeft",
            "mouthFrownRight",
        ],
    ),
    ("random", &[]),
];

/// Intensity range of the named expressions: below 0.5 most read as neutral at 512².
const EXPRESSION_INTENSITY: [f64; 2] = [0.5, 1.0];

/// Linear-RGB garment albedo per channel: real fabrics stay clear of pure black and white, and
/// albedo near 1 makes path tracing converge slowly without adding realism.
pub const GARMENT_ALBEDO: [f64; 2] = [0.03, 0.85];

/// Per-style strand parameter ranges, each sampled uniformly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HairRanges {
    pub style: &'static str,
    /// Length of the longest strands, metres.
    pub length_m: [f64; 2],
    /// Fraction of the style template's strands kept (1 = full head of hair).
    pub density: [f64; 2],
    /// Curl amplitude: 0 straight, 1 tight coils.
    pub curl: [f64; 2],
    /// Pull of strands toward their guide: 0 independent strands, 1 fully clumped.
    pub clumping: [f64; 2],
}

/// The strand parameters of each style in `spec::HAIR_STYLES`. Lengths follow the names (a buzz
/// cut is millimetres, long hair reaches past the shoulders); curly styles get the high curl
/// range and more clumping, which is how curly hair groups in practice.
pub const HAIR_RANGES: [HairRanges; 6] = [
    HairRanges {
        style: "buzz",
        length_m: [0.003, 0.012],
        density: [0.7, 1.0],
        curl: [0.0, 0.1],
        clumping: [0.0, 0.1],
    },
    HairRanges {
        style: "short",
        length_m: [0.03, 0.08],
        density: [0.6, 1.0],
        curl: [0.0, 0.3],
        clumping: [0.1, 0.4],
    },
    HairRanges {
        style: "bob",
        length_m: [0.15, 0.25],
        density: [0.6, 1.0],
        curl: [0.0, 0.3],
        clumping: [0.2, 0.5],
    },
    HairRanges {
        style: "long",
        length_m: [0.30, 0.60],
        density: [0.6, 1.0],
        curl: [0.0, 0.4],
        clumping: [0.2, 0.6],
    },
    HairRanges {
        style: "curly",
        length_m: [0.08, 0.30],
        density: [0.6, 1.0],
        curl: [0.6, 1.0],
        clumping: [0.4, 0.8],
    },
    HairRanges {
        style: "ponytail",
        length_m: [0.25, 0.50],
        density: [0.6, 1.0],
        curl: [0.0, 0.3],
        clumping: [0.3, 0.7],
    },
];

/// Which part of the dataset a sample belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    Train,
    Test,
}

/// Everything that determines one rendered sample. Field order is the JSON order and is part of
/// the sample format (it is stored in EXR headers and compared byte for byte in tests).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleSpec {
    pub index: u64,
    pub split: Split,
    pub identity: String,
    pub head: HeadSample,
    pub hair: HairSample,
    pub garment: Option<GarmentSample>,
    pub glasses: Option<AssetSample>,
    pub headset: Option<AssetSample>,
    pub camera: CameraSample,
    /// Lighting 0 and 1 of the pair; always two different HDRIs.
    pub lighting: [LightingSample; 2],
    pub render: RenderSample,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssetSample {
    pub id: String,
    pub blake3: String,
}

impl From<&AssetRef> for AssetSample {
    fn from(a: &AssetRef) -> Self {
        Self {
            id: a.id.clone(),
            blake3: a.blake3.clone(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeadSample {
    /// A catalog head's id, or "synthetic" for a generated person.
    pub id: String,
    /// The head file's hash; empty for a generated person, whose model files are pinned in
    /// `synthetic.models` instead.
    pub blake3: String,
    pub expression: Expression,
    /// The generated person (absent for catalog heads, and in samples made before they
    /// existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub synthetic: Option<SyntheticHead>,
}

/// A generated head: the person's parameters and the model files, by hash, that build it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticHead {
    pub identity: SyntheticIdentity,
    pub models: Vec<AssetSample>,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Expression {
    /// `neutral`, `smile`, `jaw_open`, `blink`, `surprise`, `frown` or `random`.
    pub name: String,
    /// ARKit blendshape name → weight in [0, 1]; a BTreeMap so the JSON order is fixed.
    pub weights: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HairSample {
    pub style: String,
    pub melanin: f64,
    pub melanin_redness: f64,
    pub density: f64,
    pub length_m: f64,
    pub curl: f64,
    pub clumping: f64,
    /// Seed of the strand geometry (root positions, jitter, curl phases).
    pub seed: u64,
    /// The fibre's longitudinal roughness βm (samples made before it had one: 0.3, the
    /// material's default).
    #[serde(default = "default_fibre_roughness")]
    pub longitudinal_roughness: f64,
    /// The fibre's azimuthal roughness βn (likewise 0.3 when absent).
    #[serde(default = "default_fibre_roughness")]
    pub azimuthal_roughness: f64,
}

fn default_fibre_roughness() -> f64 {
    0.3
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GarmentSample {
    pub id: String,
    pub blake3: String,
    /// Linear RGB albedo.
    pub color_rgb: [f64; 3],
    /// GGX roughness in [0, 1].
    pub roughness: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSample {
    /// Rotation of the camera about +Y from the subject's facing direction (+Z).
    pub yaw_deg: f64,
    /// Elevation of the camera above the subject's horizontal plane.
    pub pitch_deg: f64,
    pub radius_m: f64,
    pub fov_deg: f64,
    /// Displacement of the subject from the world origin, metres.
    pub subject_offset_m: [f64; 3],
}

impl CameraSample {
    /// Camera → world rotation, row-major, columns = the camera's right, up and back (+Z toward
    /// the viewer) axes: R_y(yaw)·R_x(−pitch), the rotation that puts the camera on its sphere
    /// (`subject::assemble::sample_camera`, which a test there checks this against).
    pub fn camera_to_world(&self) -> [[f64; 3]; 3] {
        let (sy, cy) = self.yaw_deg.to_radians().sin_cos();
        let (sp, cp) = (-self.pitch_deg).to_radians().sin_cos();
        // R_y(a) = [[c,0,s],[0,1,0],[-s,0,c]], R_x(b) = [[1,0,0],[0,c,-s],[0,s,c]].
        [
            [cy, sy * sp, sy * cp],
            [0.0, cp, -sp],
            [-sy, cy * sp, cy * cp],
        ]
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightingSample {
    pub hdri: String,
    pub blake3: String,
    /// Rotation of the environment about +Y, degrees.
    pub rotation_deg: f64,
    /// Horizontal (left-right) mirror of the environment.
    pub flip: bool,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSample {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// Seed of the renderer's per-pixel random numbers.
    pub seed: u32,
    /// The appendix passes to write (absent in samples expanded before they existed: none).
    #[serde(default)]
    pub passes: Vec<String>,
    /// Lights of the OLAT basis to render the sample under besides its two lightings (0, and
    /// absent from the JSON, when none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub olat: u32,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

/// Expands sample `index` of the dataset. `index` must be below `spec.count`.
pub fn expand(spec: &ResolvedSpec, index: u64) -> Result<SampleSpec, SceneError> {
    let invalid = |key: &str, reason: String| SceneError::Invalid {
        path: spec.source.clone(),
        key: key.to_owned(),
        reason,
    };
    if index >= spec.count {
        return Err(invalid(
            "--index",
            format!(
                "sample {index} does not exist: the dataset `{}` has count = {}, so use an index in 0..={}",
                spec.name,
                spec.count,
                spec.count.saturating_sub(1)
            ),
        ));
    }
    let stream = |s: u64| SampleRng::new(spec.seed, index, s);

    // Identity, then head; the split follows from the identity.
    // Catalog identities come first, then synthetic ids 0..count; without synthetic people
    // the draw is the one datasets made before them used.
    let mut rng = stream(STREAM_IDENTITY);
    let synthetic_count = spec.synthetic.as_ref().map_or(0, |p| p.count);
    let total = spec.identities.len() as u64 + synthetic_count;
    if total == 0 {
        return Err(invalid(
            "assets.heads",
            "selects no heads; select at least one".into(),
        ));
    }
    let pick = rng.below(total);
    let (identity_name, held_out, head, has_morphs) = match spec.identities.get(pick as usize) {
        Some(identity) => {
            let head = identity
                .heads
                .get(rng.pick(identity.heads.len()))
                .ok_or_else(|| {
                    invalid(
                        "assets.heads",
                        format!("identity {:?} has no heads", identity.name),
                    )
                })?;
            let sample = HeadSample {
                id: head.id.clone(),
                blake3: head.blake3.clone(),
                expression: Expression::default(),
                synthetic: None,
            };
            (
                identity.name.clone(),
                identity.held_out,
                sample,
                head.has_morphs,
            )
        }
        None => {
            let people = spec
                .synthetic
                .as_ref()
                .ok_or_else(|| invalid("assets.heads", "selects no synthetic people".into()))?;
            let k = pick - spec.identities.len() as u64;
            let sample = HeadSample {
                id: SYNTHETIC.to_owned(),
                blake3: String::new(),
                expression: Expression::default(),
                synthetic: Some(SyntheticHead {
                    identity: sample_identity(&people.spec, spec.seed, k),
                    models: people.models.iter().map(AssetSample::from).collect(),
                }),
            };
            // Generated heads carry the 52 ARKit Face Units.
            (identity_name(k), people.held_out(k), sample, true)
        }
    };
    let split = if held_out { Split::Test } else { Split::Train };

    // A scan or a PCA head without blendshapes cannot show an expression; asking it for one
    // would make the JSON claim a smile the image does not have.
    let expression_probability = if has_morphs {
        spec.subject.expression_probability
    } else {
        0.0
    };
    let expression = sample_expression(&mut stream(STREAM_EXPRESSION), expression_probability);
    let hair = sample_hair(
        spec,
        &mut stream(STREAM_HAIR),
        &mut stream(STREAM_HAIR_FIBRE),
    )
    .ok_or_else(|| {
        invalid(
            "subject.hair_styles",
            "is empty or names an unknown style; list styles from spec::HAIR_STYLES".into(),
        )
    })?;

    let mut rng = stream(STREAM_GARMENT);
    let garment = if !spec.garments.is_empty() && rng.bernoulli(spec.subject.garment_probability) {
        spec.garments.get(rng.pick(spec.garments.len())).map(|g| {
            let [lo, hi] = GARMENT_ALBEDO;
            let color_rgb = [
                rng.uniform(lo, hi),
                rng.uniform(lo, hi),
                rng.uniform(lo, hi),
            ];
            let [rlo, rhi] = spec.subject.garment_roughness;
            GarmentSample {
                id: g.id.clone(),
                blake3: g.blake3.clone(),
                color_rgb,
                roughness: rng.uniform(rlo, rhi),
            }
        })
    } else {
        None
    };
    let glasses = optional_asset(
        &mut stream(STREAM_GLASSES),
        spec.subject.glasses_probability,
        &spec.glasses,
    );
    let headset = optional_asset(
        &mut stream(STREAM_HEADSET),
        spec.subject.headset_probability,
        &spec.headsets,
    );

    let mut rng = stream(STREAM_CAMERA);
    let c = &spec.camera;
    let yaw_deg = rng.uniform(c.yaw_deg[0], c.yaw_deg[1]);
    let pitch_deg = rng.uniform(c.pitch_deg[0], c.pitch_deg[1]);
    let j = c.jitter_m;
    let subject_offset_m = [rng.uniform(-j, j), rng.uniform(-j, j), rng.uniform(-j, j)];
    let camera = CameraSample {
        yaw_deg,
        pitch_deg,
        radius_m: c.radius_m,
        fov_deg: c.fov_deg,
        subject_offset_m,
    };

    let lighting = sample_lighting(spec, &mut stream(STREAM_LIGHTING)).ok_or_else(|| {
        invalid(
            "assets.hdris",
            format!(
                "selects {} HDRI(s); a sample needs two different ones, so select at least 2",
                spec.hdris.len()
            ),
        )
    })?;

    // The top bits of a SplitMix64 output are as good as any; the shift makes the cast lossless.
    let seed = (stream(STREAM_RENDER).next_u64() >> 32) as u32;

    Ok(SampleSpec {
        index,
        split,
        identity: identity_name,
        head: HeadSample { expression, ..head },
        hair,
        garment,
        glasses,
        headset,
        camera,
        lighting,
        render: RenderSample {
            width: spec.width,
            height: spec.height,
            spp: spec.spp,
            seed,
            passes: spec.passes.clone(),
            olat: spec.lighting.olat,
        },
    })
}

/// [`expand`] as pretty-printed JSON (the form stored beside each sample and in golden tests).
pub fn expand_json(spec: &ResolvedSpec, index: u64) -> Result<String, SceneError> {
    let sample = expand(spec, index)?;
    // Serialising these plain structs cannot fail (string keys, finite floats), but the error
    // is mapped rather than unwrapped so a future non-finite value surfaces as an error.
    serde_json::to_string_pretty(&sample).map_err(|e| SceneError::Invalid {
        path: spec.source.clone(),
        key: "--index".to_owned(),
        reason: format!("sample {index} cannot be written as JSON ({e}); please report this"),
    })
}

fn sample_expression(rng: &mut SampleRng, probability: f64) -> Expression {
    let mut weights = BTreeMap::new();
    if !rng.bernoulli(probability) {
        return Expression {
            name: "neutral".to_owned(),
            weights,
        };
    }
    let (name, shapes) = EXPRESSIONS[rng.pick(EXPRESSIONS.len())];
    if shapes.is_empty() {
        // `random`: a partial Fisher–Yates shuffle picks 3..=6 distinct blendshapes.
        let mut order: Vec<usize> = (0..ARKIT_BLENDSHAPES.len()).collect();
        let n = 3 + rng.pick(4);
        for k in 0..n {
            let j = k + rng.pick(order.len() - k);
            order.swap(k, j);
            weights.insert(ARKIT_BLENDSHAPES[order[k]].to_owned(), rng.next_f64());
        }
    } else {
        let intensity = rng.uniform(EXPRESSION_INTENSITY[0], EXPRESSION_INTENSITY[1]);
        for shape in shapes {
            weights.insert((*shape).to_owned(), intensity);
        }
    }
    Expression {
        name: name.to_owned(),
        weights,
    }
}

/// `None` only if the spec's hair styles are empty or unknown, which validation rules out.
/// The fibre's roughness has its own stream (added later), so datasets made before it keep
/// every other hair decision.
fn sample_hair(
    spec: &ResolvedSpec,
    rng: &mut SampleRng,
    fibre: &mut SampleRng,
) -> Option<HairSample> {
    let s = &spec.subject;
    let style = s.hair_styles.get(rng.pick(s.hair_styles.len()))?;
    let r = HAIR_RANGES.iter().find(|r| r.style == style)?;
    let mut draw = |[lo, hi]: [f64; 2]| rng.uniform(lo, hi);
    Some(HairSample {
        style: style.clone(),
        melanin: draw(s.melanin),
        melanin_redness: draw(s.melanin_redness),
        density: draw(r.density),
        length_m: draw(r.length_m),
        curl: draw(r.curl),
        clumping: draw(r.clumping),
        // 53 bits: exact in every JSON reader, including JavaScript's and Python's float paths.
        seed: rng.next_u64() >> 11,
        longitudinal_roughness: fibre.uniform(
            s.hair_longitudinal_roughness[0],
            s.hair_longitudinal_roughness[1],
        ),
        azimuthal_roughness: fibre
            .uniform(s.hair_azimuthal_roughness[0], s.hair_azimuthal_roughness[1]),
    })
}

fn optional_asset(
    rng: &mut SampleRng,
    probability: f64,
    assets: &[AssetRef],
) -> Option<AssetSample> {
    if assets.is_empty() || !rng.bernoulli(probability) {
        return None;
    }
    assets.get(rng.pick(assets.len())).map(AssetSample::from)
}

/// `None` only with fewer than two HDRIs, which validation rules out.
fn sample_lighting(spec: &ResolvedSpec, rng: &mut SampleRng) -> Option<[LightingSample; 2]> {
    let n = spec.hdris.len();
    if n < 2 {
        return None;
    }
    // Draw the second from the n - 1 others by skipping over the first: uniform over ordered
    // pairs of distinct HDRIs without rejection.
    let first = rng.pick(n);
    let mut second = rng.pick(n - 1);
    if second >= first {
        second += 1;
    }
    let [lo, hi] = spec.lighting.rotation_deg;
    let mut light = |i: usize| -> Option<LightingSample> {
        let hdri = spec.hdris.get(i)?;
        Some(LightingSample {
            hdri: hdri.id.clone(),
            blake3: hdri.blake3.clone(),
            rotation_deg: rng.uniform(lo, hi),
            flip: rng.bernoulli(spec.lighting.flip_probability),
        })
    };
    Some([light(first)?, light(second)?])
}

/// Every catalog asset rendering `sample` reads: its head, garment (and the head whose body the
/// garment was fitted to, which its placement measures), glasses, headset and both HDRIs. A
/// worker fetches exactly these; an id the catalog lacks is an error naming it.
pub fn required_assets<'a>(
    sample: &SampleSpec,
    catalog: &'a Catalog,
) -> Result<Vec<&'a Asset>, SceneError> {
    let missing = |id: &str| SceneError::Invalid {
        path: catalog.root.join(crate::catalog::CATALOG_FILE),
        key: id.to_owned(),
        reason: "the sample names an asset this catalog does not have; expand the sample \
                 against the catalog it will be rendered with"
            .to_owned(),
    };
    let mut ids: Vec<&str> = match &sample.head.synthetic {
        Some(s) => s.models.iter().map(|m| m.id.as_str()).collect(),
        None => vec![sample.head.id.as_str()],
    };
    ids.extend(sample.garment.iter().map(|g| g.id.as_str()));
    ids.extend(sample.glasses.iter().map(|g| g.id.as_str()));
    ids.extend(sample.headset.iter().map(|g| g.id.as_str()));
    ids.extend(sample.lighting.iter().map(|l| l.hdri.as_str()));
    let mut out: Vec<&Asset> = Vec::with_capacity(ids.len() + 1);
    for id in ids {
        let asset = catalog.get(id).ok_or_else(|| missing(id))?;
        if let Some(body) = asset.tags.get("fitted_to") {
            out.push(catalog.get(body).ok_or_else(|| missing(body))?);
        }
        out.push(asset);
    }
    out.sort_by(|a, b| a.id.cmp(&b.id));
    out.dedup_by(|a, b| a.id == b.id);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::HAIR_STYLES;

    #[test]
    fn tables_are_complete() {
        assert_eq!(ARKIT_BLENDSHAPES.len(), 52);
        let mut names = ARKIT_BLENDSHAPES.to_vec();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), 52, "duplicate ARKit name");
        for (_, shapes) in EXPRESSIONS {
            for s in shapes {
                assert!(ARKIT_BLENDSHAPES.contains(s), "{s} is not an ARKit name");
            }
        }
        for style in HAIR_STYLES {
            assert!(
                HAIR_RANGES.iter().any(|r| r.style == style),
                "no ranges for {style}"
            );
        }
    }
}
