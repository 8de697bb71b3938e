//! `train.toml`: what to train on, how long, and the network's shape.

use std::path::{Path, PathBuf};

use lightfarm_nets::{LossWeights, Precision, RelightConfig, RenderNet};
use serde::{Deserialize, Serialize};

use crate::farm::FarmAddress;
use crate::TrainError;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// A folder export (`lightfarm export JOB --format folder --out DIR`; relative paths are
    /// relative to the config file), or a job on a coordinator, `farm://HOST:PORT/JOB`, read
    /// while it renders (`[stream]`).
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
    /// Examples per optimiser step.
    #[serde(default = "default_batch")]
    pub batch: usize,
    /// Examples per forward/backward pass when a batch does not fit the device at once: the
    /// step adds up the gradients of `batch / micro_batch` passes (`step.rs`). Default: `batch`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub micro_batch: Option<usize>,
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
    /// "f32" (default), "f16" or "bf16": the precision the convolutions train in, as PyTorch's
    /// automatic mixed precision does it (f32 weights and optimiser, f32 shading and losses; f16
    /// with a dynamic loss scale). A run may resume in another precision.
    #[serde(default)]
    pub precision: Precision,
    /// Threads decoding samples ahead of the trainer.
    #[serde(default = "default_loader_threads")]
    pub loader_threads: usize,
    #[serde(default)]
    pub net: NetConfig,
    #[serde(default)]
    pub loss: LossWeights,
    /// VGG16 weights for the perceptual loss (weight `loss.perceptual`): absent or "builtin"
    /// is the pretrained set `scripts/fetch-models.sh` installs, "none" turns the loss off, and
    /// anything else is a safetensors file in torchvision's layout, relative to the config file.
    #[serde(default)]
    pub vgg_weights: Option<PathBuf>,
    /// How a `farm://` dataset is read.
    #[serde(default)]
    pub stream: StreamConfig,
    /// Bearer token of a `farm://` dataset's coordinator: from `--token` / `LIGHTFARM_TOKEN`,
    /// never from the file (and never written to `run.json`).
    #[serde(skip)]
    pub token: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StreamConfig {
    /// CA certificate (PEM) of a TLS coordinator. Relative to the config file.
    pub tls_ca: Option<PathBuf>,
    /// Where fetched samples are kept; `<out>/sample-cache` when absent.
    pub cache_dir: Option<PathBuf>,
    /// Size bound of that cache in GiB: least recently used samples leave first.
    pub cache_gb: f64,
}

impl Default for StreamConfig {
    fn default() -> Self {
        StreamConfig {
            tls_ca: None,
            cache_dir: None,
            cache_gb: 16.0,
        }
    }
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

/// `vgg_weights` values that are not files.
pub const VGG_NONE: &str = "none";
pub const VGG_BUILTIN: &str = "builtin";

/// "none" or "builtin" rather than a path.
pub fn is_keyword(v: &Path) -> bool {
    v.to_str()
        .is_some_and(|t| t == VGG_NONE || t == VGG_BUILTIN)
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
        if !FarmAddress::is_farm(&cfg.dataset.to_string_lossy()) {
            cfg.dataset = base.join(&cfg.dataset);
        }
        cfg.stream.tls_ca = cfg.stream.tls_ca.map(|p| base.join(p));
        cfg.stream.cache_dir = cfg.stream.cache_dir.map(|p| base.join(p));
        cfg.out = base.join(&cfg.out);
        cfg.assets = cfg.assets.map(|a| base.join(a));
        cfg.vgg_weights = cfg
            .vgg_weights
            .map(|v| if is_keyword(&v) { v } else { base.join(v) });
        cfg.validate()
            .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
        Ok(cfg)
    }

    /// The perceptual loss's weights file; `None` when the loss is off.
    pub fn perceptual_weights(&self) -> Option<PathBuf> {
        if self.loss.perceptual == 0.0 {
            return None;
        }
        match self.vgg_weights.as_deref().and_then(Path::to_str) {
            Some(VGG_NONE) => None,
            None | Some(VGG_BUILTIN) => Some(lightfarm_nets::vgg::builtin_weights()),
            Some(_) => self.vgg_weights.clone(),
        }
    }

    /// Examples per forward/backward pass.
    pub fn micro_batch(&self) -> usize {
        self.micro_batch.unwrap_or(self.batch)
    }

    /// The cache directory of a streamed dataset.
    pub fn cache_dir(&self) -> PathBuf {
        self.stream
            .cache_dir
            .clone()
            .unwrap_or_else(|| self.out.join("sample-cache"))
    }

    pub fn validate(&self) -> Result<(), String> {
        let relight = self.net.relight();
        relight.validate().map_err(|e| format!("net.widths: {e}"))?;
        let multiple = relight.size_multiple();
        if let Some(text) = self.dataset.to_str().filter(|t| FarmAddress::is_farm(t)) {
            FarmAddress::parse(text).map_err(|e| e.to_string())?;
        }
        if let Some(m) = self.micro_batch {
            if m == 0 || m > self.batch || !self.batch.is_multiple_of(m) {
                return Err(format!(
                    "micro_batch = {m} must divide batch = {} (e.g. batch = 64, micro_batch = 8); leave it out to run the whole batch at once",
                    self.batch
                ));
            }
        }
        let checks: [(bool, String); 10] = [
            (
                self.stream.cache_gb.is_finite() && self.stream.cache_gb > 0.0,
                format!("stream.cache_gb = {} must be a positive number of GiB", self.stream.cache_gb),
            ),
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
