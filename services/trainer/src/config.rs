//! `train.toml`: what to train on, how long, and the network's shape.

use std::path::{Path, PathBuf};

use lightfarm_nets::{LossWeights, RelightConfig, RenderNet};
use serde::{Deserialize, Serialize};

use crate::TrainError;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// A folder export (`lightfarm export JOB --format folder --out DIR`). Relative paths are
    /// relative to the config file.
    pub dataset: PathBuf,
    /// Run directory: checkpoints, `losses.jsonl`, `run.json`. Relative to the config file.
    pub out: PathBuf,
    /// Split to train on: "train" (default), "test" or "all".
    #[serde(default = "default_split")]
    pub split: String,
    /// Asset catalog the dataset was rendered from; the built-in pack when absent.
    #[serde(default)]
    pub assets: Option<PathBuf>,
    #[serde(default = "default_steps")]
    pub steps: u64,
    #[serde(default = "default_batch")]
    pub batch: usize,
    /// Square crop side in pixels; 0 trains on whole images. A multiple of 2^(levels−1).
    #[serde(default)]
    pub crop: usize,
    #[serde(default = "default_lr")]
    pub lr: f64,
    #[serde(default)]
    pub seed: u64,
    #[serde(default = "default_checkpoint_every")]
    pub checkpoint_every: u64,
    /// Checkpoints kept besides the newest.
    #[serde(default = "default_keep")]
    pub keep_checkpoints: usize,
    /// "auto", "cpu" or "gpu".
    #[serde(default = "default_device")]
    pub device: String,
    /// Threads decoding samples ahead of the trainer.
    #[serde(default = "default_loader_threads")]
    pub loader_threads: usize,
    #[serde(default)]
    pub net: NetConfig,
    #[serde(default)]
    pub loss: LossWeights,
    /// VGG16 weights (safetensors, torchvision layout) for the perceptual loss, weighted by
    /// `loss.perceptual`; without them the loss is off. Relative to the config file.
    #[serde(default)]
    pub vgg_weights: Option<PathBuf>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NetConfig {
    /// UNet channels per level, shared by f_N, f_A, f_S and f_R.
    pub widths: Vec<usize>,
    /// "decomposed" (the paper) or "blackbox" (its ablation "w/o improved render net").
    pub render_net: RenderNet,
    /// First-layer channels of the PatchGAN critic.
    pub critic_width: usize,
    /// Step from which the adversarial loss is on (the critic trains from step 0).
    pub adversarial_from: u64,
}

impl Default for NetConfig {
    fn default() -> Self {
        NetConfig {
            widths: vec![32, 64, 128, 256, 512],
            render_net: RenderNet::Decomposed,
            critic_width: 32,
            adversarial_from: 0,
        }
    }
}

impl NetConfig {
    pub fn relight(&self) -> RelightConfig {
        RelightConfig::new()
            .with_widths(self.widths.clone())
            .with_render_net(self.render_net)
    }
}

fn default_split() -> String {
    "train".into()
}
fn default_steps() -> u64 {
    1000
}
fn default_batch() -> usize {
    4
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
fn default_loader_threads() -> usize {
    2
}

impl TrainConfig {
    /// Reads and validates `path`; relative paths inside are resolved against its directory.
    pub fn load(path: &Path) -> Result<TrainConfig, TrainError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
        let mut cfg: TrainConfig = toml::from_str(&text)
            .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
        let base = path.parent().unwrap_or(Path::new("."));
        cfg.dataset = base.join(&cfg.dataset);
        cfg.out = base.join(&cfg.out);
        cfg.assets = cfg.assets.map(|a| base.join(a));
        cfg.vgg_weights = cfg.vgg_weights.map(|v| base.join(v));
        cfg.validate()
            .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
        Ok(cfg)
    }

    pub fn validate(&self) -> Result<(), String> {
        let relight = self.net.relight();
        relight.validate().map_err(|e| format!("net.widths: {e}"))?;
        let multiple = relight.size_multiple();
        let checks: [(bool, String); 9] = [
            ((1..=100_000_000).contains(&self.steps), format!("steps = {} must be in 1..=100000000", self.steps)),
            ((1..=512).contains(&self.batch), format!("batch = {} must be in 1..=512", self.batch)),
            (
                self.crop.is_multiple_of(multiple) && self.crop <= 8192,
                format!("crop = {} must be 0 (whole images) or a multiple of {multiple} up to 8192 for {} UNet levels", self.crop, relight.widths.len()),
            ),
            (self.lr.is_finite() && self.lr > 0.0 && self.lr < 1.0, format!("lr = {} must be in (0, 1)", self.lr)),
            (self.checkpoint_every >= 1, "checkpoint_every must be at least 1".into()),
            (["train", "test", "all"].contains(&self.split.as_str()), format!("split = \"{}\" must be train, test or all", self.split)),
            ((1..=64).contains(&self.loader_threads), format!("loader_threads = {} must be in 1..=64", self.loader_threads)),
            ((1..=4096).contains(&self.net.critic_width), format!("net.critic_width = {} must be in 1..=4096", self.net.critic_width)),
            (
                [self.loss.normal, self.loss.normal_lens, self.loss.albedo, self.loss.relit, self.loss.residual, self.loss.adversarial, self.loss.perceptual]
                    .iter()
                    .all(|w| w.is_finite() && *w >= 0.0),
                "loss weights must be finite and non-negative".into(),
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
