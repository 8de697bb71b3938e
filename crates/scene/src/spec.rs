//! The dataset spec: the TOML file a person writes to ask for a light-stage dataset.
//!
//! [`DatasetSpec`] is the file as written (every section optional, defaults are the values of
//! Yeh et al. 2022, section 3); [`DatasetSpec::validate`] checks every value against what the
//! renderer and the sampler accept and resolves the asset selectors against a [`Catalog`],
//! giving the [`ResolvedSpec`] that `expand` turns into samples. `examples/dataset.toml` at the
//! repository root documents the format key by key.
//!
//! Every struct denies unknown fields so that a typo (`glases_probability`) is an error rather
//! than a silently ignored key that leaves the paper default in place.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::catalog::{Asset, AssetKind, Catalog};
use crate::error::SceneError;
use crate::identity::{
    is_synthetic_name, resolve_people, synthetic_id, IdentitySpec, SyntheticPeople, SYNTHETIC,
};
use crate::rng::hash_str;
use crate::validate::{int_in, positive, probability, range_in};

/// Upper bound on `count`: far above the paper's ~300k samples, low enough that a typo with
/// extra zeros is caught before a coordinator tries to queue it.
pub const MAX_COUNT: i64 = 10_000_000;
/// Upper bound on `width` / `height` (a 16k frame is already ~3 GB of EXR layers).
pub const MAX_RESOLUTION: i64 = 16_384;
/// Upper bound on `spp` (2^20).
pub const MAX_SPP: i64 = 1_048_576;

/// Hair styles the strand generator knows; `subject.hair_styles` must be a subset.
pub const HAIR_STYLES: [&str; 6] = ["buzz", "short", "bob", "long", "curly", "ponytail"];

/// The dataset spec as written in TOML (before validation).
///
/// Integers are read as `i64` so that `count = -5` reaches [`DatasetSpec::validate`] and gets a
/// message naming the key and the accepted range, instead of a bare type error from the parser.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetSpec {
    /// The file the spec was read from (set by [`Self::load`] / [`Self::from_toml_str`], not a
    /// TOML key); validation errors name it.
    #[serde(skip)]
    pub source: PathBuf,
    /// Dataset name (required, non-empty); used for job and output names.
    pub name: String,
    /// Seed of the whole dataset: sample `i` is a pure function of `(seed, i)`.
    #[serde(default)]
    pub seed: u64,
    /// Number of samples (required), `1..=MAX_COUNT`.
    pub count: i64,
    #[serde(default = "default_resolution")]
    pub width: i64,
    #[serde(default = "default_resolution")]
    pub height: i64,
    /// Samples per pixel per lighting.
    #[serde(default = "default_spp")]
    pub spp: i64,
    /// The appendix passes each sample adds (names from [`PASS_NAMES`]; `[]` for none).
    #[serde(default = "default_passes")]
    pub passes: Vec<String>,
    #[serde(default)]
    pub assets: AssetsSpec,
    #[serde(default)]
    pub camera: CameraSpec,
    #[serde(default)]
    pub lighting: LightingSpec,
    #[serde(default)]
    pub subject: SubjectSpec,
    #[serde(default)]
    pub split: SplitSpec,
    /// The distributions synthetic people are drawn from (used when `assets.heads` has
    /// "synthetic").
    #[serde(default)]
    pub identity: IdentitySpec,
}

fn default_resolution() -> i64 {
    // The paper renders 512 x 512.
    512
}

fn default_spp() -> i64 {
    256
}

/// Every optional pass a sample can carry (the renderer's `lightfarm_render::passes::Pass`
/// names; a subject test keeps the two lists equal).
pub const PASS_NAMES: [&str; 7] = [
    "diffuse", "specular", "sss", "coat", "sheen", "shadow", "id",
];

/// The passes a spec gets unless it says otherwise.
pub const DEFAULT_PASSES: [&str; 4] = ["diffuse", "specular", "shadow", "id"];

fn default_passes() -> Vec<String> {
    DEFAULT_PASSES.iter().map(|s| s.to_string()).collect()
}

/// `[assets]`: catalog selectors per asset kind (see `Catalog::select`: `"*"`, an asset id, or
/// `"tag:key=value"`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AssetsSpec {
    pub heads: Vec<String>,
    pub hdris: Vec<String>,
    pub garments: Vec<String>,
    pub glasses: Vec<String>,
    pub headsets: Vec<String>,
}

impl Default for AssetsSpec {
    fn default() -> Self {
        let all = || vec!["*".to_owned()];
        Self {
            heads: all(),
            hdris: all(),
            garments: all(),
            glasses: all(),
            headsets: all(),
        }
    }
}

/// `[camera]`: the paper samples the camera on a sphere of fixed radius around the subject,
/// within ±45° horizontally and ±22.5° vertically of the face direction.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraSpec {
    pub yaw_deg: [f64; 2],
    pub pitch_deg: [f64; 2],
    pub radius_m: f64,
    pub fov_deg: f64,
    /// Half-size of the cube the subject's position is jittered in ("near the world centre with
    /// some randomness in the precise location").
    pub jitter_m: f64,
}

impl Default for CameraSpec {
    fn default() -> Self {
        Self {
            yaw_deg: [-45.0, 45.0],
            pitch_deg: [-22.5, 22.5],
            radius_m: 1.0,
            fov_deg: 30.0,
            jitter_m: 0.02,
        }
    }
}

/// `[lighting]`: random rotation about +Y and horizontal flip of each HDRI (paper section 3.4).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LightingSpec {
    pub rotation_deg: [f64; 2],
    pub flip_probability: f64,
    /// Also render the sample under each light of the virtual light stage's OLAT basis (0:
    /// not; the paper's stage has 168): one half-float `olatNNN` layer per light, from which
    /// `lightfarm relight-olat` forms the sample under any HDRI.
    pub olat: u32,
}

/// Most OLAT lights a sample may ask for: beyond ~300 the 4° discs of the basis touch.
pub const MAX_OLAT: u32 = 256;

impl Default for LightingSpec {
    fn default() -> Self {
        Self {
            rotation_deg: [0.0, 360.0],
            flip_probability: 0.5,
            olat: 0,
        }
    }
}

/// `[subject]`: how the synthetic human is dressed and groomed.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SubjectSpec {
    pub glasses_probability: f64,
    pub headset_probability: f64,
    pub garment_probability: f64,
    pub garment_roughness: [f64; 2],
    pub melanin: [f64; 2],
    pub melanin_redness: [f64; 2],
    /// Chiang et al. 2016's longitudinal roughness βm of the hair fibre, uniform in this range.
    pub hair_longitudinal_roughness: [f64; 2],
    /// Its azimuthal roughness βn, uniform in this range.
    pub hair_azimuthal_roughness: [f64; 2],
    pub hair_styles: Vec<String>,
    pub expression_probability: f64,
}

impl Default for SubjectSpec {
    fn default() -> Self {
        Self {
            glasses_probability: 0.2,
            headset_probability: 0.05,
            garment_probability: 1.0,
            // The paper samples roughness in 0.1..1.5 (Arnold accepts > 1); our GGX is defined
            // on [0, 1], so the default range is clamped there.
            garment_roughness: [0.1, 1.0],
            melanin: [0.0, 1.0],
            melanin_redness: [0.0, 1.0],
            // Around Chiang et al.'s 0.3 / 0.3 and Arnold aiStandardHair's 0.2 default: from
            // glossy straight hair to the duller look of coarse or curly hair.
            hair_longitudinal_roughness: [0.15, 0.4],
            hair_azimuthal_roughness: [0.25, 0.6],
            hair_styles: HAIR_STYLES.iter().map(|s| (*s).to_owned()).collect(),
            expression_probability: 0.7,
        }
    }
}

/// `[split]`: which head identities are held out for testing. At most one of the two may be set.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct SplitSpec {
    /// Identities named explicitly.
    pub test_identities: Vec<String>,
    /// Or a fraction of the selected identities, chosen deterministically from the seed.
    pub test_fraction: f64,
}

/// An asset as a sample refers to it: its id and the hash that pins its bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AssetRef {
    pub id: String,
    pub blake3: String,
    /// Heads: whether the file has the ARKit morph targets (catalog tag `morphs`); heads
    /// without them are always rendered with a neutral expression.
    pub has_morphs: bool,
}

impl AssetRef {
    pub(crate) fn of(asset: &Asset) -> Self {
        Self {
            id: asset.id.clone(),
            blake3: asset.blake3.clone(),
            has_morphs: asset.tags.contains_key("morphs"),
        }
    }
}

/// One head identity and its head assets (several scans/expressions of one person share an
/// identity; the held-out split is by identity so that no person is seen in training).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    pub name: String,
    pub heads: Vec<AssetRef>,
    pub held_out: bool,
}

/// A validated spec with every selector resolved to catalog assets; the input of `expand`.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedSpec {
    /// The file the spec came from, for error messages raised while expanding.
    pub source: PathBuf,
    pub name: String,
    pub seed: u64,
    pub count: u64,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// The passes of every sample, in [`PASS_NAMES`] order without duplicates.
    pub passes: Vec<String>,
    /// All selected identities, sorted by name (the order `expand` draws from).
    pub identities: Vec<Identity>,
    /// Selected HDRIs, at least two, in catalog order without duplicates.
    pub hdris: Vec<AssetRef>,
    pub garments: Vec<AssetRef>,
    pub glasses: Vec<AssetRef>,
    pub headsets: Vec<AssetRef>,
    pub camera: CameraSpec,
    pub lighting: LightingSpec,
    pub subject: SubjectSpec,
    /// Synthetic people, when `assets.heads` selects them.
    pub synthetic: Option<SyntheticPeople>,
}

impl ResolvedSpec {
    /// Names of the held-out identities, sorted.
    #[must_use]
    pub fn test_identities(&self) -> Vec<&str> {
        self.identities
            .iter()
            .filter(|i| i.held_out)
            .map(|i| i.name.as_str())
            .collect()
    }

    /// Names of the training identities, sorted.
    #[must_use]
    pub fn train_identities(&self) -> Vec<&str> {
        self.identities
            .iter()
            .filter(|i| !i.held_out)
            .map(|i| i.name.as_str())
            .collect()
    }
}

impl DatasetSpec {
    /// Reads and parses a spec file (no validation: call [`Self::validate`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, SceneError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Parses spec text; `path` only labels error messages.
    pub fn from_toml_str(text: &str, path: impl AsRef<Path>) -> Result<Self, SceneError> {
        // toml's message carries line, column and (for typos) "unknown field `x`, expected one
        // of ...", which is the fix the user needs.
        let path = path.as_ref();
        let mut spec: Self = toml::from_str(text).map_err(|e| SceneError::Toml {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        spec.source = path.to_path_buf();
        Ok(spec)
    }

    /// Checks every value and resolves the asset selectors against `catalog`.
    pub fn validate(&self, catalog: &Catalog) -> Result<ResolvedSpec, SceneError> {
        let source = self.source.as_path();
        let bad = |key: &str, reason: String| SceneError::Invalid {
            path: source.to_path_buf(),
            key: key.to_owned(),
            reason,
        };

        if self.name.trim().is_empty() {
            return Err(bad(
                "name",
                "must not be empty: give the dataset a name, e.g. name = \"demo\"".into(),
            ));
        }
        let count = int_in("count", self.count, 1, MAX_COUNT, &bad)?;
        let width = int_in("width", self.width, 1, MAX_RESOLUTION, &bad)?;
        let height = int_in("height", self.height, 1, MAX_RESOLUTION, &bad)?;
        let spp = int_in("spp", self.spp, 1, MAX_SPP, &bad)?;
        for p in &self.passes {
            if !PASS_NAMES.contains(&p.as_str()) {
                return Err(bad(
                    "passes",
                    format!(
                        "has unknown pass '{p}': use any of {} (or [] for none)",
                        PASS_NAMES.join(", ")
                    ),
                ));
            }
        }
        let passes: Vec<String> = PASS_NAMES
            .iter()
            .filter(|n| self.passes.iter().any(|p| p == *n))
            .map(|n| n.to_string())
            .collect();

        // Camera. Pitch stays strictly inside ±90° because the look-at frame uses +Y as up and
        // degenerates at the poles.
        let c = &self.camera;
        range_in("camera.yaw_deg", c.yaw_deg, -180.0, 180.0, &bad)?;
        range_in("camera.pitch_deg", c.pitch_deg, -89.0, 89.0, &bad)?;
        positive("camera.radius_m", c.radius_m, &bad)?;
        if !(c.fov_deg > 0.0 && c.fov_deg < 180.0) {
            return Err(bad(
                "camera.fov_deg",
                format!(
                    "is {}; a pinhole field of view must be in (0, 180) degrees, e.g. 30",
                    c.fov_deg
                ),
            ));
        }
        if !(c.jitter_m.is_finite() && c.jitter_m >= 0.0 && c.jitter_m < c.radius_m) {
            return Err(bad(
                "camera.jitter_m",
                format!(
                    "is {}; it must be >= 0 and below camera.radius_m ({}) so the camera stays outside the jitter cube, e.g. 0.02",
                    c.jitter_m, c.radius_m
                ),
            ));
        }

        // Lighting.
        let l = &self.lighting;
        range_in("lighting.rotation_deg", l.rotation_deg, -720.0, 720.0, &bad)?;
        probability("lighting.flip_probability", l.flip_probability, &bad)?;
        if l.olat == 1 || l.olat > MAX_OLAT {
            return Err(bad(
                "lighting.olat",
                format!(
                    "is {}; use 0 (no OLAT images) or 2..={MAX_OLAT} lights (the paper's light \
                     stage has 168)",
                    l.olat
                ),
            ));
        }

        // Subject.
        let s = &self.subject;
        probability("subject.glasses_probability", s.glasses_probability, &bad)?;
        probability("subject.headset_probability", s.headset_probability, &bad)?;
        probability("subject.garment_probability", s.garment_probability, &bad)?;
        probability(
            "subject.expression_probability",
            s.expression_probability,
            &bad,
        )?;
        // GGX roughness is defined on [0, 1]; the paper's 1.5 upper end is an Arnold extension.
        range_in(
            "subject.garment_roughness",
            s.garment_roughness,
            0.0,
            1.0,
            &bad,
        )?;
        range_in("subject.melanin", s.melanin, 0.0, 1.0, &bad)?;
        range_in("subject.melanin_redness", s.melanin_redness, 0.0, 1.0, &bad)?;
        range_in(
            "subject.hair_longitudinal_roughness",
            s.hair_longitudinal_roughness,
            0.0,
            1.0,
            &bad,
        )?;
        range_in(
            "subject.hair_azimuthal_roughness",
            s.hair_azimuthal_roughness,
            0.0,
            1.0,
            &bad,
        )?;
        if s.hair_styles.is_empty() {
            return Err(bad(
                "subject.hair_styles",
                format!("is empty; list at least one of {HAIR_STYLES:?}"),
            ));
        }
        for style in &s.hair_styles {
            if !HAIR_STYLES.contains(&style.as_str()) {
                return Err(bad(
                    "subject.hair_styles",
                    format!("unknown hair style {style:?}; use one of {HAIR_STYLES:?}"),
                ));
            }
        }

        // Assets.
        let a = &self.assets;
        // `Catalog::select` labels its errors with the catalog file, but the key to edit is in
        // this spec, so the path is swapped for the spec's.
        let select = |kind: AssetKind, selectors: &[String], key: &str| {
            catalog.select(kind, selectors, key).map_err(|e| match e {
                SceneError::Invalid { key, reason, .. } => SceneError::Invalid {
                    path: source.to_path_buf(),
                    key,
                    reason,
                },
                other => other,
            })
        };
        // "synthetic" is not a catalog selector: it adds generated people (`[identity]`).
        let wants_synthetic = a.heads.iter().any(|h| h == SYNTHETIC);
        let catalog_selectors: Vec<String> = a
            .heads
            .iter()
            .filter(|h| *h != SYNTHETIC)
            .cloned()
            .collect();
        let heads = if catalog_selectors.is_empty() && wants_synthetic {
            Vec::new()
        } else {
            select(AssetKind::Head, &catalog_selectors, "assets.heads")?
        };
        let synthetic = if wants_synthetic {
            Some(resolve_people(&self.identity, self.seed, catalog, &bad)?)
        } else {
            None
        };
        let hdris = select(AssetKind::Hdri, &a.hdris, "assets.hdris")?;
        let garments = select(AssetKind::Garment, &a.garments, "assets.garments")?;
        let glasses = select(AssetKind::Glasses, &a.glasses, "assets.glasses")?;
        let headsets = select(AssetKind::Headset, &a.headsets, "assets.headsets")?;
        if hdris.len() < 2 {
            return Err(bad(
                "assets.hdris",
                format!(
                    "selects {} HDRI(s); each sample lights the subject under two different HDRIs, so select at least 2 (e.g. [\"*\"])",
                    hdris.len()
                ),
            ));
        }
        // A probability with nothing to draw from would silently never fire; say so instead.
        for (key, p, list, kind) in [
            (
                "subject.glasses_probability",
                s.glasses_probability,
                &glasses,
                "assets.glasses",
            ),
            (
                "subject.headset_probability",
                s.headset_probability,
                &headsets,
                "assets.headsets",
            ),
            (
                "subject.garment_probability",
                s.garment_probability,
                &garments,
                "assets.garments",
            ),
        ] {
            if p > 0.0 && list.is_empty() {
                return Err(bad(
                    key,
                    format!(
                        "is {p} but {kind} selects no assets; set it to 0 or select some in {kind}"
                    ),
                ));
            }
        }

        // Identities: a head without an explicit identity is its own identity. `select` returns
        // each asset once, so no head is counted twice.
        let mut by_identity: BTreeMap<String, Vec<AssetRef>> = BTreeMap::new();
        for head in heads {
            let name = head.identity.clone().unwrap_or_else(|| head.id.clone());
            by_identity
                .entry(name)
                .or_default()
                .push(AssetRef::of(head));
        }
        if by_identity.is_empty() && synthetic.is_none() {
            return Err(bad(
                "assets.heads",
                "selects no heads; select at least one (e.g. [\"*\"] or [\"synthetic\"])".into(),
            ));
        }
        let synthetic_count = synthetic.as_ref().map_or(0, |p| p.count);
        let held_out = self.held_out_identities(&by_identity, synthetic_count, &bad)?;
        let synthetic = synthetic.map(|mut p| {
            p.held_out_names = held_out
                .iter()
                .filter(|n| is_synthetic_name(n))
                .cloned()
                .collect();
            p.held_out_fraction = self.split.test_fraction;
            p
        });
        let held_catalog = held_out.iter().filter(|n| !is_synthetic_name(n)).count();
        if synthetic.is_none() && held_catalog == by_identity.len() {
            return Err(bad(
                "split",
                format!(
                    "holds out all {} selected identities, leaving no training data; hold out fewer (shorten split.test_identities or lower split.test_fraction) or select more heads in assets.heads",
                    by_identity.len()
                ),
            ));
        }
        let identities = by_identity
            .into_iter()
            .map(|(name, heads)| Identity {
                // A fraction is applied to the catalog and the synthetic people separately,
                // so that mixing in generated people leaves the scans' split as it was.
                held_out: held_out.contains(&name),
                name,
                heads,
            })
            .collect();

        Ok(ResolvedSpec {
            source: source.to_path_buf(),
            name: self.name.clone(),
            seed: self.seed,
            count,
            width: u32::try_from(width).unwrap_or(u32::MAX),
            height: u32::try_from(height).unwrap_or(u32::MAX),
            spp: u32::try_from(spp).unwrap_or(u32::MAX),
            passes,
            identities,
            hdris: hdris.iter().map(|a| AssetRef::of(a)).collect(),
            garments: garments.iter().map(|a| AssetRef::of(a)).collect(),
            glasses: glasses.iter().map(|a| AssetRef::of(a)).collect(),
            headsets: headsets.iter().map(|a| AssetRef::of(a)).collect(),
            camera: self.camera.clone(),
            lighting: self.lighting.clone(),
            subject: self.subject.clone(),
            synthetic,
        })
    }

    /// Resolves `[split]` to the set of held-out identity names.
    ///
    /// With `test_fraction = f`, `ceil(f * n)` identities are held out (so any non-zero fraction
    /// holds out at least one): those whose `hash_str(seed, name)` is smallest. Hashing the name
    /// rather than using catalog order keeps the choice stable when assets are added.
    fn held_out_identities(
        &self,
        identities: &BTreeMap<String, Vec<AssetRef>>,
        synthetic_count: u64,
        bad: &dyn Fn(&str, String) -> SceneError,
    ) -> Result<BTreeSet<String>, SceneError> {
        let sp = &self.split;
        probability("split.test_fraction", sp.test_fraction, bad)?;
        if !sp.test_identities.is_empty() && sp.test_fraction > 0.0 {
            return Err(bad(
                "split",
                "sets both test_identities and test_fraction; keep one of them".into(),
            ));
        }
        let mut held = BTreeSet::new();
        for name in &sp.test_identities {
            let synthetic = synthetic_id(name).is_some_and(|k| k < synthetic_count);
            if !identities.contains_key(name) && !synthetic {
                let known: Vec<&str> = identities.keys().map(String::as_str).collect();
                return Err(bad(
                    "split.test_identities",
                    format!("{name:?} is not the identity of any head selected by assets.heads; use one of {known:?}"),
                ));
            }
            held.insert(name.clone());
        }
        if sp.test_fraction > 0.0 {
            let n = identities.len();
            // n is small (hundreds), so the f64 product is exact enough; ceil keeps any
            // non-zero fraction from rounding to no held-out identity at all.
            let want = ((sp.test_fraction * n as f64).ceil() as usize).min(n);
            let mut ranked: Vec<(u64, &String)> = identities
                .keys()
                .map(|name| (hash_str(self.seed, name), name))
                .collect();
            ranked.sort();
            held.extend(ranked.into_iter().take(want).map(|(_, name)| name.clone()));
        }
        Ok(held)
    }
}
