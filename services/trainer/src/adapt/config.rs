//! `adapt.toml`: which trained model to adapt, on which photos, how long, and the ablations of
//! the paper's Table 4.

use std::path::{Path, PathBuf};

use lightfarm_nets::{AdaptTarget, AdaptWeights};
use serde::{Deserialize, Serialize};

use crate::config::{is_keyword, VGG_BUILTIN, VGG_NONE};
use crate::TrainError;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdaptConfig {
    /// The model trained on renders: a run directory (its newest checkpoint) or a checkpoint
    /// directory. It stays frozen. Relative to the config file.
    pub base: PathBuf,
    /// A folder of real portraits (JPEG or PNG, searched recursively). Relative to the config
    /// file.
    pub photos: PathBuf,
    /// Run directory: checkpoints (each a complete model for `relight`), `losses.jsonl`,
    /// `adapt.json`, and the prepared photos (`photo-cache/`).
    pub out: PathBuf,
    /// Asset catalog the HDRIs come from; the built-in pack when absent.
    #[serde(default)]
    pub assets: Option<PathBuf>,
    #[serde(default = "default_steps")]
    pub steps: u64,
    #[serde(default = "default_batch")]
    pub batch: usize,
    /// Side in pixels of the square crop each photo is resized to (the paper: 512). A
    /// multiple of both networks' size multiples.
    #[serde(default = "default_size")]
    pub size: usize,
    /// The paper's learning rate.
    #[serde(default = "default_lr")]
    pub lr: f64,
    #[serde(default)]
    pub seed: u64,
    #[serde(default = "default_checkpoint_every")]
    pub checkpoint_every: u64,
    #[serde(default = "default_keep")]
    pub keep_checkpoints: usize,
    /// "auto", "cpu" or "gpu".
    #[serde(default = "default_device")]
    pub device: String,
    /// "albedo" (the paper: f_Ā refines the albedo) or "relit" (the ablation "direct
    /// syn2real": a residual on the relit image).
    #[serde(default = "default_target")]
    pub target: AdaptTarget,
    /// The ablation "finetune only" (Table 4): no f_Ā; every network of the base model trains
    /// on the photos with the same losses (relative consistency still against the frozen
    /// original). Checkpoints are then plain models.
    #[serde(default)]
    pub finetune: bool,
    /// The loss weights; an ablation sets one to 0 ("w/o relative consistency": `relative`,
    /// "w/o OLAT consistency": `olat`).
    #[serde(default)]
    pub weights: AdaptWeights,
    #[serde(default)]
    pub adapter: AdapterShape,
    /// Catalog HDRIs the relative consistency loss relights under (two per step, random
    /// rotations); empty: every HDRI of the catalog.
    #[serde(default)]
    pub hdris: Vec<String>,
    /// Lights of the OLAT basis the OLAT consistency loss draws two from (the paper's light
    /// stage: 168). Each light's prefiltered maps are computed once per run, on first use.
    #[serde(default = "default_olat_lights")]
    pub olat_lights: usize,
    /// First-layer channels of the PatchGAN critic (real photos against R̄).
    #[serde(default = "default_critic_width")]
    pub critic_width: usize,
    /// VGG16 weights of the similarity loss: absent or "builtin" (fetch-models.sh), "none"
    /// (then `weights.similarity` must be 0), or a safetensors file.
    #[serde(default)]
    pub vgg_weights: Option<PathBuf>,
}

/// f_Ā's shape: the paper's is 32 channels first and 9 residual blocks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdapterShape {
    pub base: usize,
    pub blocks: usize,
}

impl Default for AdapterShape {
    fn default() -> Self {
        AdapterShape {
            base: 32,
            blocks: 9,
        }
    }
}

fn default_steps() -> u64 {
    2000
}
fn default_batch() -> usize {
    4
}
fn default_size() -> usize {
    256
}
fn default_lr() -> f64 {
    1e-4
}
fn default_checkpoint_every() -> u64 {
    100
}
fn default_keep() -> usize {
    2
}
fn default_device() -> String {
    "auto".into()
}
fn default_target() -> AdaptTarget {
    AdaptTarget::Albedo
}
fn default_olat_lights() -> usize {
    lightfarm_light::OLAT_LIGHTS
}
fn default_critic_width() -> usize {
    32
}

impl AdaptConfig {
    /// Reads and validates `path`; relative paths inside are resolved against its directory.
    pub fn load(path: &Path) -> Result<AdaptConfig, TrainError> {
        let bad = |e: String| TrainError::Config(format!("{}: {e}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let mut cfg: AdaptConfig = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        cfg.base = dir.join(&cfg.base);
        cfg.photos = dir.join(&cfg.photos);
        cfg.out = dir.join(&cfg.out);
        cfg.assets = cfg.assets.map(|a| dir.join(a));
        cfg.vgg_weights = cfg
            .vgg_weights
            .map(|v| if is_keyword(&v) { v } else { dir.join(v) });
        cfg.validate().map_err(bad)?;
        Ok(cfg)
    }

    /// The similarity loss's VGG16 weights; None when that loss is off.
    pub fn similarity_weights(&self) -> Option<PathBuf> {
        if self.weights.similarity == 0.0 {
            return None;
        }
        match self.vgg_weights.as_deref().and_then(Path::to_str) {
            Some(VGG_NONE) => None,
            None | Some(VGG_BUILTIN) => Some(lightfarm_nets::vgg::builtin_weights()),
            Some(_) => self.vgg_weights.clone(),
        }
    }

    pub fn validate(&self) -> Result<(), String> {
        let w = &self.weights;
        let checks: [(bool, String); 11] = [
            (
                !(self.finetune && self.target != AdaptTarget::Albedo),
                "finetune = true trains the base networks themselves; `target` is where f_Ā's residual goes, so leave it at \"albedo\"".into(),
            ),
            (
                (2..=256).contains(&self.olat_lights),
                format!("olat_lights = {} must be in 2..=256 (the paper's stage has 168)", self.olat_lights),
            ),
            ((1..=100_000_000).contains(&self.steps), format!("steps = {} must be in 1..=100000000", self.steps)),
            ((1..=512).contains(&self.batch), format!("batch = {} must be in 1..=512", self.batch)),
            (
                (16..=2048).contains(&self.size),
                format!("size = {} must be in 16..=2048 pixels", self.size),
            ),
            (self.lr.is_finite() && self.lr > 0.0 && self.lr < 1.0, format!("lr = {} must be in (0, 1)", self.lr)),
            (self.checkpoint_every >= 1, "checkpoint_every must be at least 1".into()),
            ((1..=4096).contains(&self.critic_width), format!("critic_width = {} must be in 1..=4096", self.critic_width)),
            (
                [w.olat, w.relative, w.similarity, w.identity, w.gan].iter().all(|v| v.is_finite() && *v >= 0.0),
                "weights must be finite and non-negative".into(),
            ),
            (
                w.olat + w.relative + w.similarity + w.identity + w.gan > 0.0,
                "every loss weight is 0: nothing would train".into(),
            ),
            (
                !(w.similarity > 0.0 && self.vgg_weights.as_deref().and_then(Path::to_str) == Some(VGG_NONE)),
                "vgg_weights = \"none\" turns off the similarity loss: also set weights.similarity = 0".into(),
            ),
        ];
        for (ok, msg) in checks {
            if !ok {
                return Err(msg);
            }
        }
        Ok(())
    }
}
