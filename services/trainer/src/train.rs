//! The training loop, its loss log, and resumable checkpoints.
//!
//! A run directory holds `run.json` (the resolved config), `losses.jsonl` (one line per step)
//! and `checkpoints/step-NNNNNNNNN/` with the generator and critic weights (safetensors), both
//! Adam states and `state.json`; `checkpoints/latest` names the newest complete one. A
//! checkpoint is written to a temporary directory and renamed, and `latest` is replaced by
//! rename, so `kill -9` at any moment leaves the previous checkpoint intact. Batches are a pure
//! function of (seed, step) and the samples drawn from, so a resumed run continues the same
//! loss curve; for a `farm://` dataset the checkpoint keeps that sample set (`stream.json`).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use burn::optim::ModuleOptimizer;
use lightfarm_nets::{
    load_weights, save_weights, stable_param_ids, PatchGan, PatchGanConfig, RelightNet, Vgg16,
};
use lightfarm_scene::Catalog;
use serde::{Deserialize, Serialize};

use crate::config::TrainConfig;
use crate::data::{Dataset, PrefetchParams, Prefetcher};
use crate::farm::{FarmAddress, FarmOptions, FarmSource, StreamState, STREAM_FILE};
use crate::lights::LightCache;
use crate::loss_scale::LossScale;
use crate::step::{self, StepSpec};
use crate::TrainError;

/// Held while a run seeds Burn and initialises its networks. Burn's seed is process-wide: two
/// runs initialising at once (trainer service, tests) would interleave their draws, and a
/// resumed run would no longer match its first start.
pub(crate) static SEED_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

pub const RUN_FILE: &str = "run.json";
pub const LOSS_FILE: &str = "losses.jsonl";
pub const CHECKPOINTS: &str = "checkpoints";
pub const LATEST: &str = "latest";
pub const MODEL_FILE: &str = "model.safetensors";
const CRITIC_FILE: &str = "critic.safetensors";
const OPTIM_FILE: &str = "optim.bpk";
const CRITIC_OPTIM_FILE: &str = "critic_optim.bpk";
pub(crate) const STATE_FILE: &str = "state.json";
/// The network shape next to its weights, so a checkpoint directory is a self-contained model.
pub const NET_FILE: &str = "net.json";

/// One line of `losses.jsonl`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepLog {
    pub step: u64,
    pub total: f32,
    pub normal: f32,
    pub normal_lens: f32,
    pub albedo: f32,
    pub relit: f32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adversarial: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub critic: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub perceptual: Option<f32>,
    pub samples_per_second: f32,
    /// Samples the step drew from (a streamed dataset's grows at checkpoints).
    #[serde(default)]
    pub dataset_samples: u64,
}

#[derive(Serialize, Deserialize)]
struct CheckpointState {
    /// Steps completed: training resumes at this step.
    step: u64,
    /// f16's loss scale; absent in f32/bf16 runs and in checkpoints from before precision.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    loss_scale: Option<LossScale>,
}

#[derive(Clone, Debug)]
pub struct TrainSummary {
    pub start_step: u64,
    pub end_step: u64,
    pub checkpoint: PathBuf,
    pub cancelled: bool,
}

/// What training reports as it goes; `on_step` runs after every step.
pub trait Observer {
    fn on_start(&mut self, _start: u64, _end: u64) {}
    fn on_step(&mut self, _log: &StepLog) {}
}

impl Observer for () {}

/// Trains `cfg` to `cfg.steps`, resuming from the run directory's newest checkpoint. Stops
/// early, after a checkpoint, when `cancel` is set.
pub fn train(
    cfg: &TrainConfig,
    catalog: Catalog,
    observer: &mut dyn Observer,
    cancel: &AtomicBool,
) -> Result<TrainSummary, TrainError> {
    fs::create_dir_all(cfg.out.join(CHECKPOINTS)).map_err(|e| TrainError::io(&cfg.out, e))?;
    check_run_file(cfg)?;
    let base = lightfarm_nets::device::select(&cfg.device)
        .map_err(|e| TrainError::Config(e.to_string()))?;
    cfg.precision
        .check(&base)
        .map_err(|e| TrainError::Config(e.to_string()))?;
    let device = base.autodiff();
    let init_guard = SEED_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    device.seed(cfg.seed);

    let model = cfg
        .net
        .relight()
        .init(&device)
        .map_err(|e| TrainError::Config(e.to_string()))?;
    let mut model = stable_param_ids(model, 1);
    let mut critic = stable_param_ids(
        PatchGanConfig::new()
            .with_width(cfg.net.critic_width)
            .init(&device),
        2,
    );
    drop(init_guard);
    let vgg = cfg
        .perceptual_weights()
        .map(|path| Vgg16::load(&path, &device))
        .transpose()
        .map_err(|e| {
            TrainError::Config(format!(
                "vgg_weights: {e}; or set vgg_weights = \"none\" to train without the perceptual loss"
            ))
        })?;
    let mut optim = lightfarm_nets::optimizer();
    let mut critic_optim = lightfarm_nets::optimizer();
    let mut start = 0u64;
    let mut resume_stream = None;
    let mut scale = LossScale::new(cfg.precision);
    if let Some(dir) = latest_checkpoint(&cfg.out)? {
        let saved;
        (
            Trainable {
                model,
                critic,
                optim,
                critic_optim,
            },
            saved,
        ) = load_checkpoint(
            &dir,
            Trainable {
                model,
                critic,
                optim,
                critic_optim,
            },
        )?;
        start = saved.step;
        // A run that resumes in another precision starts that precision's scale afresh.
        scale = saved
            .loss_scale
            .filter(|s| s.dynamic == scale.dynamic)
            .unwrap_or(scale);
        resume_stream = StreamState::load(&dir)?;
        tracing::info!(step = start, checkpoint = %dir.display(), "resuming");
    }
    truncate_losses(&cfg.out.join(LOSS_FILE), start)?;
    observer.on_start(start, cfg.steps);
    if start >= cfg.steps {
        let checkpoint = latest_checkpoint(&cfg.out)?.unwrap_or_default();
        return Ok(TrainSummary {
            start_step: start,
            end_step: start,
            checkpoint,
            cancelled: false,
        });
    }

    let dataset = Arc::new(open_dataset(cfg, resume_stream, cancel)?);
    let lights = Arc::new(LightCache::new(catalog));
    let prefetcher = |from: u64| {
        Prefetcher::start(
            dataset.clone(),
            dataset.items(),
            lights.clone(),
            PrefetchParams {
                seed: cfg.seed,
                batch: cfg.batch,
                crop: cfg.crop,
                start: from,
                end: cfg.steps,
                threads: cfg.loader_threads,
            },
        )
    };
    let mut prefetch = prefetcher(start);
    let multiple = cfg.net.relight().size_multiple();
    let mut log = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(cfg.out.join(LOSS_FILE))
        .map_err(|e| TrainError::io(&cfg.out.join(LOSS_FILE), e))?;
    let mut checkpoint = PathBuf::new();
    let mut step = start;
    let mut cancelled = false;
    while step < cfg.steps {
        let started = Instant::now();
        let examples = prefetch.next_batch()?;
        let drawn_from = prefetch.items() as u64;
        let size = examples[0].size;
        if size % multiple != 0 {
            return Err(TrainError::Config(format!(
                "images are {size} px; with {} UNet levels they must be a multiple of {multiple}: set `crop` to a multiple of {multiple}",
                cfg.net.widths.len()
            )));
        }
        let grads = step::gradients(
            &model,
            &critic,
            &examples,
            &device,
            &StepSpec {
                micro_batch: cfg.micro_batch(),
                weights: &cfg.loss,
                adversarial: step >= cfg.net.adversarial_from && cfg.loss.adversarial > 0.0,
                train_critic: cfg.loss.adversarial > 0.0,
                vgg: vgg.as_ref(),
                precision: cfg.precision,
                loss_scale: scale,
            },
        )?;
        let loss = grads.losses;
        if !loss.total.is_finite() {
            return Err(TrainError::Diverged {
                step,
                loss: loss.total,
            });
        }
        let tried = scale.scale;
        if scale.update(grads.finite) {
            model = optim.step(cfg.lr, model, grads.model);
            if let Some(g) = grads.critic {
                critic = critic_optim.step(cfg.lr, critic, g);
            }
        } else if tried <= 1.0 {
            // Overflow with nothing left to scale down: the gradients themselves blew up.
            return Err(TrainError::Diverged {
                step,
                loss: f32::INFINITY,
            });
        } else {
            tracing::warn!(
                step = step + 1,
                loss_scale = tried,
                next = scale.scale,
                "f16 gradients overflowed: step skipped, loss scale halved"
            );
        }
        step += 1;
        let entry = StepLog {
            step,
            total: loss.total,
            normal: loss.normal,
            normal_lens: loss.normal_lens,
            albedo: loss.albedo,
            relit: loss.relit,
            residual: loss.residual,
            adversarial: loss.adversarial,
            critic: loss.critic,
            perceptual: loss.perceptual,
            samples_per_second: examples.len() as f32 / started.elapsed().as_secs_f32().max(1e-9),
            dataset_samples: drawn_from,
        };
        let line = serde_json::to_string(&entry).map_err(|e| TrainError::Config(e.to_string()))?;
        writeln!(log, "{line}").map_err(|e| TrainError::io(&cfg.out.join(LOSS_FILE), e))?;
        observer.on_step(&entry);
        cancelled = cancel.load(Ordering::Relaxed);
        if step.is_multiple_of(cfg.checkpoint_every) || step == cfg.steps || cancelled {
            log.flush()
                .map_err(|e| TrainError::io(&cfg.out.join(LOSS_FILE), e))?;
            // A stream's new samples join here, and the checkpoint records the set that steps
            // from here on draw from, so a resumed run draws the same batches.
            let grew = step.is_multiple_of(cfg.checkpoint_every)
                && step < cfg.steps
                && dataset.refresh()?;
            let stream = dataset.stream_state();
            checkpoint = save_checkpoint(
                &cfg.out,
                step,
                (&model, &critic, &optim, &critic_optim),
                stream.as_deref(),
                scale.dynamic.then_some(scale),
                cfg,
            )?;
            if grew {
                tracing::info!(
                    step,
                    samples = dataset.len(),
                    "new samples of the stream join training"
                );
                prefetch = prefetcher(step);
            }
        }
        if cancelled {
            break;
        }
    }
    Ok(TrainSummary {
        start_step: start,
        end_step: step,
        checkpoint,
        cancelled,
    })
}

/// Writes `run.json` on the first run; later runs must have the same network and data, or the
/// checkpoints there would be resumed into the wrong model.
fn check_run_file(cfg: &TrainConfig) -> Result<(), TrainError> {
    let path = cfg.out.join(RUN_FILE);
    if let Ok(text) = fs::read_to_string(&path) {
        let old: TrainConfig = serde_json::from_str(&text).map_err(|e| {
            TrainError::Config(format!(
                "{}: unreadable ({e}); move the run directory away",
                path.display()
            ))
        })?;
        if old.net != cfg.net
            || old.seed != cfg.seed
            || old.batch != cfg.batch
            || old.crop != cfg.crop
        {
            return Err(TrainError::Config(format!(
                "{} was trained with a different net/seed/batch/crop; resume with the same settings \
                 or give this config another `out` directory",
                cfg.out.display()
            )));
        }
    }
    let text = serde_json::to_string_pretty(cfg).map_err(|e| TrainError::Config(e.to_string()))?;
    write_atomic(&path, text.as_bytes())
}

pub fn latest_checkpoint(out: &Path) -> Result<Option<PathBuf>, TrainError> {
    let latest = out.join(CHECKPOINTS).join(LATEST);
    match fs::read_to_string(&latest) {
        Ok(name) => {
            let dir = out.join(CHECKPOINTS).join(name.trim());
            if dir.join(STATE_FILE).is_file() {
                Ok(Some(dir))
            } else {
                Err(TrainError::Checkpoint(format!(
                    "{} names {}, which is incomplete; delete {} to start over",
                    latest.display(),
                    dir.display(),
                    latest.display()
                )))
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(TrainError::io(&latest, e)),
    }
}

/// A folder export, or a coordinator job followed from `resume`'s snapshot (a checkpoint's) or
/// from its first sample.
fn open_dataset(
    cfg: &TrainConfig,
    resume: Option<StreamState>,
    cancel: &AtomicBool,
) -> Result<Dataset, TrainError> {
    let text = cfg.dataset.to_string_lossy();
    if !FarmAddress::is_farm(&text) {
        return Dataset::open(&cfg.dataset, &cfg.split);
    }
    let addr = FarmAddress::parse(&text)?;
    let token = cfg.token.as_deref().ok_or_else(|| {
        TrainError::Config(format!(
            "dataset {text}: the coordinator's token is needed: pass --token or set LIGHTFARM_TOKEN"
        ))
    })?;
    let opts = FarmOptions {
        token,
        tls_ca: cfg.stream.tls_ca.as_deref(),
        cache_dir: cfg.cache_dir(),
        cache_bytes: (cfg.stream.cache_gb * (1u64 << 30) as f64) as u64,
        split: &cfg.split,
        crop: cfg.crop,
    };
    Ok(Dataset::farm(FarmSource::open(
        &addr, &opts, resume, cancel,
    )?))
}

type Modules<'a> = (
    &'a RelightNet,
    &'a PatchGan,
    &'a ModuleOptimizer,
    &'a ModuleOptimizer,
);

fn save_checkpoint(
    out: &Path,
    step: u64,
    (model, critic, optim, critic_optim): Modules<'_>,
    stream: Option<&StreamState>,
    loss_scale: Option<LossScale>,
    cfg: &TrainConfig,
) -> Result<PathBuf, TrainError> {
    let tmp = begin_checkpoint(out, step)?;
    let ck = |e: String| TrainError::Checkpoint(e);
    save_weights(model, &tmp.join(MODEL_FILE)).map_err(|e| ck(e.to_string()))?;
    save_weights(critic, &tmp.join(CRITIC_FILE)).map_err(|e| ck(e.to_string()))?;
    optim
        .save(tmp.join(OPTIM_FILE))
        .map_err(|e| ck(format!("optimizer state: {e:?}")))?;
    critic_optim
        .save(tmp.join(CRITIC_OPTIM_FILE))
        .map_err(|e| ck(format!("critic optimizer state: {e:?}")))?;
    let net = serde_json::to_vec_pretty(&cfg.net).map_err(|e| ck(e.to_string()))?;
    write_atomic(&tmp.join(NET_FILE), &net)?;
    let state =
        serde_json::to_vec(&CheckpointState { step, loss_scale }).map_err(|e| ck(e.to_string()))?;
    write_atomic(&tmp.join(STATE_FILE), &state)?;
    if let Some(stream) = stream {
        let bytes = serde_json::to_vec(stream).map_err(|e| ck(e.to_string()))?;
        write_atomic(&tmp.join(STREAM_FILE), &bytes)?;
    }
    publish_checkpoint(out, step, cfg.keep_checkpoints)
}

/// The name of step `step`'s checkpoint under `checkpoints/`.
fn checkpoint_name(step: u64) -> String {
    format!("step-{step:09}")
}

/// An empty temporary directory for step `step`'s checkpoint (a leftover of a killed run is
/// cleared); [`publish_checkpoint`] makes it the newest.
pub(crate) fn begin_checkpoint(out: &Path, step: u64) -> Result<PathBuf, TrainError> {
    let tmp = out
        .join(CHECKPOINTS)
        .join(format!(".{}.partial", checkpoint_name(step)));
    if tmp.exists() {
        fs::remove_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    }
    fs::create_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    Ok(tmp)
}

/// Syncs and renames the temporary directory of [`begin_checkpoint`] into place, points
/// `latest` at it and prunes all but `keep` older checkpoints; returns its path.
pub(crate) fn publish_checkpoint(
    out: &Path,
    step: u64,
    keep: usize,
) -> Result<PathBuf, TrainError> {
    let root = out.join(CHECKPOINTS);
    let name = checkpoint_name(step);
    let tmp = root.join(format!(".{name}.partial"));
    let dir = root.join(&name);
    sync_dir(&tmp);
    if dir.exists() {
        fs::remove_dir_all(&dir).map_err(|e| TrainError::io(&dir, e))?;
    }
    fs::rename(&tmp, &dir).map_err(|e| TrainError::io(&dir, e))?;
    write_atomic(&root.join(LATEST), name.as_bytes())?;
    prune(&root, &name, keep);
    Ok(dir)
}

/// What a checkpoint restores besides its `state.json`: the weights and both optimizers.
struct Trainable {
    model: RelightNet,
    critic: PatchGan,
    optim: ModuleOptimizer,
    critic_optim: ModuleOptimizer,
}

fn load_checkpoint(
    dir: &Path,
    nets: Trainable,
) -> Result<(Trainable, CheckpointState), TrainError> {
    let ck = |e: String| TrainError::Checkpoint(format!("{}: {e}", dir.display()));
    let model = load_weights(nets.model, &dir.join(MODEL_FILE)).map_err(|e| ck(e.to_string()))?;
    let critic =
        load_weights(nets.critic, &dir.join(CRITIC_FILE)).map_err(|e| ck(e.to_string()))?;
    let optim = nets
        .optim
        .load(dir.join(OPTIM_FILE))
        .map_err(|e| ck(format!("optimizer state: {e:?}")))?;
    let critic_optim = nets
        .critic_optim
        .load(dir.join(CRITIC_OPTIM_FILE))
        .map_err(|e| ck(format!("critic optimizer state: {e:?}")))?;
    let state: CheckpointState = serde_json::from_slice(
        &fs::read(dir.join(STATE_FILE)).map_err(|e| TrainError::io(dir, e))?,
    )
    .map_err(|e| ck(format!("{STATE_FILE}: {e}")))?;
    let nets = Trainable {
        model,
        critic,
        optim,
        critic_optim,
    };
    Ok((nets, state))
}

/// Drops loss lines past `step` (any JSON line with a `step`): steps after the checkpoint are
/// redone on resume. Serves training and adaptation logs alike.
pub(crate) fn truncate_losses(path: &Path, step: u64) -> Result<(), TrainError> {
    let Ok(text) = fs::read_to_string(path) else {
        return Ok(());
    };
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| {
            serde_json::from_str::<serde_json::Value>(l)
                .ok()
                .and_then(|v| v["step"].as_u64())
                .is_some_and(|s| s <= step)
        })
        .collect();
    let mut out = kept.join("\n");
    if !out.is_empty() {
        out.push('\n');
    }
    write_atomic(path, out.as_bytes())
}

pub fn read_losses(out: &Path) -> Result<Vec<StepLog>, TrainError> {
    let path = out.join(LOSS_FILE);
    let text = fs::read_to_string(&path).map_err(|e| TrainError::io(&path, e))?;
    Ok(text
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect())
}

fn prune(root: &Path, newest: &str, keep: usize) {
    let Ok(entries) = fs::read_dir(root) else {
        return;
    };
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("step-") && n.as_str() != newest)
        .collect();
    names.sort();
    let excess = names.len().saturating_sub(keep);
    for n in &names[..excess] {
        let _ = fs::remove_dir_all(root.join(n));
    }
}

pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    let tmp = path.with_extension("tmp");
    let mut f = fs::File::create(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    f.write_all(bytes).map_err(|e| TrainError::io(&tmp, e))?;
    f.sync_all().map_err(|e| TrainError::io(&tmp, e))?;
    fs::rename(&tmp, path).map_err(|e| TrainError::io(path, e))
}

fn sync_dir(dir: &Path) {
    if let Ok(entries) = fs::read_dir(dir) {
        for e in entries.flatten() {
            if let Ok(f) = fs::File::open(e.path()) {
                let _ = f.sync_all();
            }
        }
    }
}
