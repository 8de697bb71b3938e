//! Synthetic identities: `[identity]` of a spec (the distributions people are drawn from) and
//! identity *k*'s parameters, a pure function of (dataset seed, k).
//!
//! A spec selects them with `[assets] heads = ["synthetic"]`, alone or next to catalog
//! selectors. Every parameter a generator reads is in [`SyntheticIdentity`], which the sample
//! JSON carries, so a sample can be rebuilt bit for bit from its record and the model files it
//! names by hash.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use crate::catalog::{AssetKind, Catalog};
use crate::error::SceneError;
use crate::rng::{hash_str, SampleRng};
use crate::spec::AssetRef;
use crate::validate::{int_in, probability, range_in, weights};

/// The selector in `[assets] heads` that adds synthetic people.
pub const SYNTHETIC: &str = "synthetic";

/// Bumped whenever the same parameters would build a different person; samples record it and
/// a worker refuses a record made by another version.
pub const GENERATOR: &str = "makehuman-ict-4";

/// Identity streams are keyed by (seed, k, stream), separate from the per-sample streams of
/// `expand`, so every sample of identity k sees the same person.
const STREAM_SHAPE: u64 = 101;
const STREAM_SKIN: u64 = 102;
const STREAM_ICT: u64 = 103;

/// The ICT Face Model light has 100 identity modes; each person gets a coefficient for each.
pub const ICT_MODES: usize = 100;
/// ICT coefficients are truncated at this many standard deviations: beyond it a PCA model's
/// faces leave the range of the scans it was fitted to.
pub const ICT_TRUNCATION: f64 = 2.5;
/// A domain tag folded into the seed so identity k and sample k never share a state.
const IDENTITY_DOMAIN: u64 = 0x1D_E471_7150_0000;

/// `[identity]`: how synthetic people are drawn.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IdentitySpec {
    /// How many distinct synthetic people the dataset draws from (ids 0..count).
    pub count: i64,
    /// Age in years, uniform.
    pub age_years: [f64; 2],
    /// Probability that a person is male (MakeHuman's gender macro at 1; female at 0).
    pub male_fraction: f64,
    /// Relative weights of the dominant ancestry of MakeHuman's ethnic macro:
    /// African, Asian, Caucasian. A person's mix is mostly the dominant one.
    pub ancestry: [f64; 3],
    /// Relative frequency of the six skin-tone categories (ITA° classes very light, light,
    /// intermediate, tan, brown, dark — the Fitzpatrick I–VI proxy of the skin model).
    pub skin_types: [f64; 6],
    /// Standard deviation of each face-shape modifier (MakeHuman slider units).
    pub face_shape_sd: f64,
    /// Standard deviation of the asymmetry modifiers.
    pub asymmetry_sd: f64,
    /// Standard deviation of the ICT Face Model's identity coefficients (light-stage scans of
    /// real faces; 1 = the scanned people's spread, 0 = no ICT shape).
    pub ict_shape_sd: f64,
    /// MakeHuman's muscle and weight macros (0.5 = average), uniform: the body build.
    pub muscle: [f64; 2],
    pub weight: [f64; 2],
    /// Volume fraction of blood in the dermis, uniform.
    pub haemoglobin: [f64; 2],
    /// Share of eumelanin in the melanin, uniform.
    pub eumelanin_ratio: [f64; 2],
    /// Freckle density in [0, 1]: 0 none; drawn uniformly, then scaled down for dark skin.
    pub freckles: [f64; 2],
}

impl Default for IdentitySpec {
    fn default() -> Self {
        Self {
            count: 100_000,
            // The paper's scans: ages 18-76, 247 male / 265 female.
            age_years: [18.0, 76.0],
            male_fraction: 0.5,
            ancestry: [1.0, 1.0, 1.0],
            skin_types: [1.0; 6],
            // The ICT modes carry most of a face's own shape (they come from scans); the
            // MakeHuman modifiers add a little of theirs.
            face_shape_sd: 0.1,
            asymmetry_sd: 0.1,
            ict_shape_sd: 1.0,
            muscle: [0.3, 0.7],
            weight: [0.25, 0.8],
            // Donner & Jensen 2006 / Jimenez 2010: 0.2 %-7 % blood; most faces 1-4 %.
            haemoglobin: [0.01, 0.05],
            eumelanin_ratio: [0.6, 0.9],
            freckles: [0.0, 1.0],
        }
    }
}

/// Skin parameters of one person (the skin model turns the category and its position into a
/// melanin fraction).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkinParams {
    /// Skin-tone category 1..=6 (ITA° class).
    pub category: u8,
    /// Where in the category's ITA° interval the person's cheek lies, 0 = lightest end.
    pub tone: f64,
    pub haemoglobin: f64,
    pub eumelanin_ratio: f64,
    pub freckles: f64,
    /// Seed of the texture detail: freckle and mole positions, pores, blotches.
    pub texture_seed: u64,
}

/// Every parameter of synthetic person `id`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticIdentity {
    pub generator: String,
    pub id: u64,
    /// 0 female, 1 male.
    pub gender: f64,
    pub age_years: f64,
    pub muscle: f64,
    pub weight: f64,
    /// MakeHuman's ethnic macro: African, Asian, Caucasian shares summing to 1.
    pub ancestry: [f64; 3],
    pub face_shape_sd: f64,
    pub asymmetry_sd: f64,
    /// Seed of the face-shape modifiers.
    pub shape_seed: u64,
    /// Coefficients of the ICT Face Model's identity modes, first mode first (empty: none).
    pub ict_shape: Vec<f64>,
    pub skin: SkinParams,
    /// Stromal melanin of the iris: 0 blue, ~0.45 green-hazel, 1 dark brown.
    pub iris_melanin: f64,
}

/// The identity name of synthetic person `id` (what splits and sample records use).
pub fn identity_name(id: u64) -> String {
    format!("synthetic-{id:07}")
}

/// Index of a draw from non-negative `weights` (validated to have a positive sum).
fn weighted(rng: &mut SampleRng, weights: &[f64]) -> usize {
    let total: f64 = weights.iter().sum();
    let mut x = rng.next_f64() * total;
    for (i, w) in weights.iter().enumerate() {
        if x < *w {
            return i;
        }
        x -= w;
    }
    // Rounding can leave x at the very end; the last non-zero weight takes it.
    weights.iter().rposition(|w| *w > 0.0).unwrap_or(0)
}

/// Person `id` of a dataset seeded with `seed`.
pub fn sample_identity(spec: &IdentitySpec, seed: u64, id: u64) -> SyntheticIdentity {
    let key = seed ^ IDENTITY_DOMAIN;
    let mut rng = SampleRng::new(key, id, STREAM_SHAPE);
    let gender = if rng.bernoulli(spec.male_fraction) {
        1.0
    } else {
        0.0
    };
    let age_years = rng.uniform(spec.age_years[0], spec.age_years[1]);
    let muscle = rng.uniform(spec.muscle[0], spec.muscle[1]);
    let weight = rng.uniform(spec.weight[0], spec.weight[1]);
    // A dominant ancestry with 60-100 % of the mix, the rest spread over the other two.
    let dominant = weighted(&mut rng, &spec.ancestry);
    let share = rng.uniform(0.6, 1.0);
    let split = rng.next_f64();
    let mut ancestry = [0.0; 3];
    ancestry[dominant] = share;
    ancestry[(dominant + 1) % 3] = (1.0 - share) * split;
    ancestry[(dominant + 2) % 3] = (1.0 - share) * (1.0 - split);
    let shape_seed = rng.next_u64() >> 11;

    let mut rng = SampleRng::new(key, id, STREAM_SKIN);
    let category = weighted(&mut rng, &spec.skin_types) as u8 + 1;
    let tone = rng.next_f64();
    let haemoglobin = rng.uniform(spec.haemoglobin[0], spec.haemoglobin[1]);
    let eumelanin_ratio = rng.uniform(spec.eumelanin_ratio[0], spec.eumelanin_ratio[1]);
    // Freckles are an ephelides trait of light skin: full density for category 1, none by 5.
    let freckle_scale = [1.0, 0.8, 0.45, 0.15, 0.0, 0.0][usize::from(category - 1)];
    let freckles = rng.uniform(spec.freckles[0], spec.freckles[1]) * freckle_scale;
    let texture_seed = rng.next_u64() >> 11;
    // A stream of its own, so the other parameters of identity k are those of earlier
    // generators.
    let mut ict = SampleRng::new(key, id, STREAM_ICT);
    let ict_shape = if spec.ict_shape_sd > 0.0 {
        (0..ICT_MODES)
            .map(|_| ict.normal(ICT_TRUNCATION) * spec.ict_shape_sd)
            .collect()
    } else {
        Vec::new()
    };
    // Iris colour follows skin tone: light irises occur almost only with light skin (the
    // exponent skews light categories towards blue and grey, dark ones to brown).
    let c = usize::from(category - 1);
    let iris_floor = [0.0, 0.0, 0.2, 0.5, 0.7, 0.8][c];
    let iris_skew = [2.0, 1.4, 1.0, 0.7, 0.5, 0.5][c];
    let iris_melanin = iris_floor + (1.0 - iris_floor) * libm::pow(rng.next_f64(), iris_skew);
    SyntheticIdentity {
        generator: GENERATOR.to_owned(),
        id,
        gender,
        age_years,
        muscle,
        weight,
        ancestry,
        face_shape_sd: spec.face_shape_sd,
        asymmetry_sd: spec.asymmetry_sd,
        shape_seed,
        ict_shape,
        skin: SkinParams {
            category,
            tone,
            haemoglobin,
            eumelanin_ratio,
            freckles,
            texture_seed,
        },
        iris_melanin,
    }
}

/// The largest `identity.count`: ids are printed with 7 digits.
pub const MAX_SYNTHETIC: i64 = 10_000_000;

/// The model assets synthetic people are generated from.
pub const SYNTHETIC_MODELS: [&str; 3] = ["makehuman_core", "makehuman_targets", "ict_face_model"];

pub(crate) fn is_synthetic_name(name: &str) -> bool {
    synthetic_id(name).is_some()
}

/// `synthetic-0000042` → 42.
pub fn synthetic_id(name: &str) -> Option<u64> {
    let digits = name.strip_prefix("synthetic-")?;
    (digits.len() == 7 && digits.bytes().all(|b| b.is_ascii_digit()))
        .then(|| digits.parse().ok())
        .flatten()
}

/// The synthetic identities of a resolved spec: ids `0..count`, drawn after the catalog
/// identities (an identity draw picks uniformly among catalog and synthetic people together).
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticPeople {
    pub spec: IdentitySpec,
    pub count: u64,
    /// The model files that generate them (catalog kind `model`, tag `model = "makehuman"`).
    pub models: Vec<AssetRef>,
    /// Held out by name (`split.test_identities`).
    pub held_out_names: BTreeSet<String>,
    /// Held out by `split.test_fraction`: identity k is held out when its seeded hash falls
    /// below this fraction of the hash range (so the held-out set needs no list).
    pub held_out_fraction: f64,
    /// The dataset seed the fraction's hash is keyed by.
    pub seed: u64,
}

impl SyntheticPeople {
    /// Whether synthetic identity `id` is in the test split.
    #[must_use]
    pub fn held_out(&self, id: u64) -> bool {
        let name = identity_name(id);
        if self.held_out_names.contains(&name) {
            return true;
        }
        // 2^64 * f in f64; the top 53 bits of the hash compared with f scaled to 2^53 is exact.
        let h = hash_str(self.seed, &name) >> 11;
        (h as f64) < self.held_out_fraction * (1u64 << 53) as f64
    }
}

/// Validates `[identity]` and finds the model files synthetic people need; the held-out
/// fields are filled in by the split.
pub(crate) fn resolve_people(
    p: &IdentitySpec,
    seed: u64,
    catalog: &Catalog,
    bad: &dyn Fn(&str, String) -> SceneError,
) -> Result<SyntheticPeople, SceneError> {
    let count = int_in("identity.count", p.count, 1, MAX_SYNTHETIC, bad)?;
    range_in("identity.age_years", p.age_years, 1.0, 90.0, bad)?;
    probability("identity.male_fraction", p.male_fraction, bad)?;
    weights("identity.ancestry", &p.ancestry, bad)?;
    weights("identity.skin_types", &p.skin_types, bad)?;
    for (key, v) in [
        ("identity.face_shape_sd", p.face_shape_sd),
        ("identity.asymmetry_sd", p.asymmetry_sd),
    ] {
        if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
            return Err(bad(
                key,
                format!("is {v}; it must be in [0, 1] (0.1 with the ICT shapes, 0.25 without, is a natural spread)"),
            ));
        }
    }
    if !(p.ict_shape_sd.is_finite() && (0.0..=2.0).contains(&p.ict_shape_sd)) {
        return Err(bad(
            "identity.ict_shape_sd",
            format!(
                "is {}; it must be in [0, 2] (1 is the spread of the scanned faces, 0 turns the ICT shapes off)",
                p.ict_shape_sd
            ),
        ));
    }
    range_in("identity.muscle", p.muscle, 0.0, 1.0, bad)?;
    range_in("identity.weight", p.weight, 0.0, 1.0, bad)?;
    range_in("identity.haemoglobin", p.haemoglobin, 0.0, 0.2, bad)?;
    range_in("identity.eumelanin_ratio", p.eumelanin_ratio, 0.0, 1.0, bad)?;
    range_in("identity.freckles", p.freckles, 0.0, 1.0, bad)?;
    let mut models = Vec::new();
    for id in SYNTHETIC_MODELS {
        let asset = catalog.get(id).filter(|a| a.kind == AssetKind::Model).ok_or_else(|| {
            bad(
                "assets.heads",
                format!(
                    "selects \"synthetic\" but the catalog at {} has no model asset `{id}`: use the built-in asset pack",
                    catalog.root.display()
                ),
            )
        })?;
        if !catalog.path_of(asset).is_file() {
            return Err(bad(
                "assets.heads",
                format!(
                    "selects \"synthetic\" but {}",
                    catalog.missing_file_reason(asset)
                ),
            ));
        }
        models.push(AssetRef::of(asset));
    }
    Ok(SyntheticPeople {
        spec: p.clone(),
        count,
        models,
        held_out_names: BTreeSet::new(),
        held_out_fraction: 0.0,
        seed,
    })
}
