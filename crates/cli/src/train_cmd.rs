//! `lightfarm train`, `relight` and `eval`: the trainer crate behind a progress bar.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_trainer::config::TrainConfig;
use lightfarm_trainer::eval::{evaluate, table};
use lightfarm_trainer::eval_real::{evaluate_real, real_table, RealEvalOptions};
use lightfarm_trainer::image_io::{gray_png_bytes, load_portrait, write_png};
use lightfarm_trainer::infer::{load_model, normal_colours, resolve_model_dir};
use lightfarm_trainer::lights::{camera_to_env, identity_camera, Lighting};
use lightfarm_trainer::train::RUN_FILE;
use lightfarm_trainer::{Observer, StepLog};

use crate::spec_cmd::load_catalog;

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Training config (TOML): dataset, out, steps, batch, crop, lr, net, loss.
    pub config: PathBuf,
    /// Override `steps` (resuming a finished run to a larger count continues it).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Override `device`: auto, cpu or gpu.
    #[arg(long, env = "LIGHTFARM_TRAIN_DEVICE")]
    pub device: Option<String>,
    /// Override `precision`: f32, or f16 / bf16 for the convolutions (mixed precision with f32
    /// weights; f16 with a dynamic loss scale). A trainer service reads it from the config.
    #[arg(long, conflicts_with = "trainer")]
    pub precision: Option<lightfarm_nets::Precision>,
    /// Submit to a trainer service (`lightfarm serve trainer`) instead of training here, and
    /// follow the job; `dataset` then names a folder export under the trainer's --datasets.
    #[arg(long, env = "LIGHTFARM_TRAINER")]
    pub trainer: Option<String>,
    /// Dataset on the trainer: a folder export under its --datasets, or a coordinator job
    /// `farm://HOST:PORT/JOB` as the trainer reaches it (overrides the config's `dataset`).
    #[arg(long, requires = "trainer")]
    pub dataset: Option<String>,
    /// Bearer token of the trainer service, or of the coordinator of a `farm://HOST:PORT/JOB`
    /// dataset.
    #[arg(long, env = "LIGHTFARM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

struct Bar(ProgressBar);

impl Observer for Bar {
    fn on_start(&mut self, start: u64, end: u64) {
        self.0.set_length(end);
        self.0.set_position(start);
        self.0.reset_eta();
    }

    fn on_step(&mut self, l: &StepLog) {
        self.0.set_position(l.step);
        self.0.set_message(format!(
            "loss {:.4} (relit {:.4}, normal {:.4}, albedo {:.4}) {:.1} samples/s",
            l.total, l.relit, l.normal, l.albedo, l.samples_per_second
        ));
    }
}

/// Sets the returned flag on Ctrl-C or SIGTERM, so training stops after a checkpoint.
pub(crate) fn cancel_on_signal() -> Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    let rt = crate::farm_cmd::runtime()?;
    let f = flag.clone();
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            rt.block_on(crate::farm_cmd::shutdown_signal());
            eprintln!("stopping after the current step (checkpointing)…");
            f.store(true, Ordering::Relaxed);
        })
        .context("starting the signal thread")?;
    Ok(flag)
}

pub fn train(a: TrainArgs) -> Result<()> {
    if let Some(url) = a.trainer.clone() {
        return crate::farm_cmd::runtime()?.block_on(remote_train(url, a));
    }
    let mut cfg = TrainConfig::load(&a.config)?;
    if let Some(s) = a.steps {
        cfg.steps = s;
    }
    if let Some(d) = a.device {
        cfg.device = d;
    }
    if let Some(p) = a.precision {
        cfg.precision = p;
    }
    cfg.token = a.token.clone();
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.config.display()))?;
    let catalog = load_catalog(&cfg.assets)?;
    let cancel = cancel_on_signal()?;
    let bar = ProgressBar::new(cfg.steps).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps  eta {eta}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut observer = Bar(bar.clone());
    let summary = lightfarm_trainer::train(&cfg, catalog, &mut observer, &cancel)?;
    bar.finish();
    println!(
        "{} steps {}..{}; checkpoint {}; loss curve {}",
        if summary.cancelled {
            "stopped at"
        } else {
            "trained"
        },
        summary.start_step,
        summary.end_step,
        summary.checkpoint.display(),
        cfg.out.join(lightfarm_trainer::train::LOSS_FILE).display()
    );
    Ok(())
}

/// Submits the config to a trainer service and follows the job to its end.
async fn remote_train(url: String, a: TrainArgs) -> Result<()> {
    use lightfarm_proto::v1 as pb;
    let text = std::fs::read_to_string(&a.config)
        .with_context(|| format!("reading {}", a.config.display()))?;
    let mut client = crate::remote_job::connect(&url, a.token)?;
    let job = client
        .submit_train_job(pb::SubmitTrainJobRequest {
            config_toml: text,
            dataset: a.dataset.unwrap_or_default(),
            split: String::new(),
            steps: a.steps.unwrap_or(0),
            batch: 0,
        })
        .await
        .map_err(|s| anyhow::anyhow!("--trainer {url}: {}", s.message()))?
        .into_inner();
    crate::remote_job::follow(&mut client, job, |l| {
        format!(
            "loss {:.4} (relit {:.4}) {:.1} samples/s",
            l.total, l.relit, l.samples_per_second
        )
    })
    .await
}

#[derive(Args, Debug)]
pub struct TrainJobsArgs {
    /// The trainer service.
    #[arg(
        long,
        env = "LIGHTFARM_TRAINER",
        default_value = "http://127.0.0.1:7071"
    )]
    pub trainer: String,
    /// Bearer token of the trainer service.
    #[arg(long, env = "LIGHTFARM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

/// One line per job: id, state, step/steps, dataset (an adaptation job: its photos and base
/// job), error.
pub fn train_jobs(a: TrainJobsArgs) -> Result<()> {
    use lightfarm_proto::v1 as pb;
    crate::farm_cmd::runtime()?.block_on(async {
        let mut client = crate::remote_job::connect(&a.trainer, a.token)?;
        let jobs = client
            .list_train_jobs(pb::ListTrainJobsRequest {})
            .await
            .map_err(|s| anyhow::anyhow!("--trainer {}: {}", a.trainer, s.message()))?
            .into_inner()
            .jobs;
        println!("{:<28} {:<10} {:>15}  dataset", "job", "state", "step");
        for j in jobs {
            let state = pb::TrainJobState::try_from(j.state)
                .map(|s| {
                    s.as_str_name()
                        .trim_start_matches("TRAIN_JOB_STATE_")
                        .to_lowercase()
                })
                .unwrap_or_else(|_| format!("state {}", j.state));
            let step = format!("{}/{}", j.step, j.steps);
            let error = if j.error.is_empty() {
                String::new()
            } else {
                format!("  error: {}", j.error)
            };
            let base = if j.base_job_id.is_empty() {
                String::new()
            } else {
                format!(" (adapting {})", j.base_job_id)
            };
            println!(
                "{:<28} {:<10} {:>15}  {}{base}{error}",
                j.id, state, step, j.dataset
            );
        }
        Ok(())
    })
}

#[derive(Args, Debug)]
pub struct RelightArgs {
    /// A run directory (newest checkpoint), a checkpoint directory or its model.safetensors.
    #[arg(long)]
    pub model: PathBuf,
    /// Portrait: PNG/JPEG (sRGB; alpha = mask), an RGB(A) EXR, or a lightfarm sample EXR.
    #[arg(long)]
    pub image: PathBuf,
    /// Foreground mask (white = subject); default: the image's alpha, a sample's coverage, or
    /// for a photo without alpha the matte of MODNet (installed by ./scripts/fetch-models.sh).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Do not matte a photo without alpha or --mask: all of it is the subject.
    #[arg(long)]
    pub no_matte: bool,
    #[command(flatten)]
    pub target: crate::olat_cmd::TargetHdri,
    /// Relit image (PNG) with the diffuse and mirror balls inset; the network's normal,
    /// albedo and light maps go next to it as OUT_normal.png etc.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, env = "LIGHTFARM_TRAIN_DEVICE", default_value = "auto")]
    pub device: String,
}

fn load_lighting(hdri: &str, assets: &Option<PathBuf>) -> Result<Lighting> {
    Ok(Lighting::load(&crate::olat_cmd::hdri_path(hdri, assets)?)?)
}

pub fn relight(a: RelightArgs) -> Result<()> {
    crate::render_cmd::ensure_parent(&a.out, "--out")?;
    let model = load_model(&a.model, &a.device)?;
    let matting = lightfarm_photo::LazyMatting::builtin();
    let portrait = load_portrait(
        &a.image,
        a.mask.as_deref(),
        (!a.no_matte).then_some(&matting),
    )?;
    let t = &a.target;
    let lighting = load_lighting(&t.hdri, &t.assets)?;
    let lighting_sample = lightfarm_scene::expand::LightingSample {
        hdri: t.hdri.clone(),
        blake3: String::new(),
        rotation_deg: f64::from(t.rotation),
        flip: t.flip,
    };
    // A rendered sample knows its camera; a photograph is taken from the HDRI's front (−Z).
    let rot = match &portrait.sample {
        Some(s) => camera_to_env(s.spec.camera.camera_to_world(), &lighting_sample, false),
        None => identity_camera(t.rotation, t.flip),
    };
    let (w, h) = (portrait.width, portrait.height);
    let r = model.relight(&portrait.rgb, &portrait.mask, w, h, &lighting, rot)?;

    let composed = r.with_inset(&lighting, rot);
    write_png(&a.out, w, h, &composed)?;
    let stem = a.out.with_extension("");
    let side = |name: &str| PathBuf::from(format!("{}_{name}.png", stem.display()));
    write_png(&side("normal"), w, h, &normal_colours(&r.normal))?;
    write_png(&side("normal_lens"), w, h, &normal_colours(&r.normal_lens))?;
    write_png(&side("albedo"), w, h, &r.albedo)?;
    write_png(&side("diffuse"), w, h, &r.diffuse)?;
    write_png(&side("specular"), w, h, &r.specular)?;
    let mask_png = side("mask");
    std::fs::write(&mask_png, gray_png_bytes(w, h, &portrait.mask)?)
        .with_context(|| format!("writing {}", mask_png.display()))?;
    println!(
        "wrote {} (+ _normal, _normal_lens, _albedo, _diffuse, _specular, _mask) with model {}{}",
        a.out.display(),
        model.dir.display(),
        if portrait.matted {
            "; the foreground is MODNet's matte of the photo (_mask.png; --mask or --no-matte to change it)"
        } else {
            ""
        }
    );
    Ok(())
}

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Models to compare (run or checkpoint directories); one row each.
    #[arg(long, required = true)]
    pub model: Vec<PathBuf>,
    /// Folder export to evaluate on (default: the first model's training dataset).
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Held-out identities are the "test" split.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Also write the rows as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[arg(long, env = "LIGHTFARM_TRAIN_DEVICE", default_value = "auto")]
    pub device: String,
    #[arg(long)]
    pub assets: Option<PathBuf>,
    /// LPIPS (VGG) weights for the LPIPS column: "builtin" (the pretrained ones that
    /// ./scripts/fetch-models.sh installs), a safetensors file (torchvision's VGG16 `features.*`
    /// plus the lpips package's `lin0..4`; README: "LPIPS and the perceptual loss"), or "none".
    #[arg(long, default_value = "builtin")]
    pub lpips: String,
    /// Evaluate on a folder of real portraits (JPEG/PNG) instead of a dataset: identity kept
    /// (dlib), FD-VGG/KID realism and OLAT consistency, the metrics of the paper's Table 4.
    #[arg(long, conflicts_with_all = ["dataset", "split"])]
    pub real: Option<PathBuf>,
    /// With --real: HDRI relightings per photo.
    #[arg(long, default_value_t = 4, requires = "real")]
    pub lightings: usize,
    /// With --real: side of the square photos are prepared at.
    #[arg(long, default_value_t = 256, requires = "real")]
    pub size: usize,
    /// With --real: seed of the lightings drawn per photo.
    #[arg(long, default_value_t = 0, requires = "real")]
    pub seed: u64,
}

/// Where prepared photos are kept between evaluations.
fn photo_cache() -> PathBuf {
    std::env::var_os("LIGHTFARM_CACHE")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache/lightfarm")))
        .unwrap_or_else(std::env::temp_dir)
        .join("photo-cache")
}

fn eval_real(a: &EvalArgs, photos: &Path) -> Result<()> {
    if !(1..=64).contains(&a.lightings) {
        bail!("--lightings {} must be in 1..=64", a.lightings);
    }
    if !(32..=2048).contains(&a.size) {
        bail!("--size {} must be in 32..=2048 pixels", a.size);
    }
    let vgg = match lpips_weights(&a.lpips)? {
        Some(p) => p,
        None => bail!("--real needs VGG16 weights for FD-VGG and KID: drop --lpips none"),
    };
    let run = run_config_of(&a.model[0]);
    let assets = a.assets.clone().or_else(|| run.and_then(|r| r.assets));
    let catalog = load_catalog(&assets)?;
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} photos  eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let opts = RealEvalOptions {
        photos: photos.to_owned(),
        cache: photo_cache(),
        size: a.size,
        lightings: a.lightings,
        seed: a.seed,
        vgg,
        device: a.device.clone(),
    };
    let (rows, skipped) = evaluate_real(&a.model, &opts, catalog, |i, n| {
        bar.set_length(n as u64);
        bar.set_position(i as u64);
    })?;
    bar.finish_and_clear();
    print!("{}", real_table(&rows));
    if skipped > 0 {
        println!("{skipped} photo(s) skipped (named in the log with the reason)");
    }
    if let Some(path) = &a.json {
        crate::render_cmd::ensure_parent(path, "--json")?;
        std::fs::write(path, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The run a model came from (run.json two levels above its checkpoint), for its dataset.
fn run_config_of(model: &Path) -> Option<TrainConfig> {
    let dir = resolve_model_dir(model).ok()?;
    let run = dir.parent()?.parent()?.join(RUN_FILE);
    serde_json::from_str(&std::fs::read_to_string(run).ok()?).ok()
}

pub fn eval(a: EvalArgs) -> Result<()> {
    if let Some(photos) = &a.real {
        return eval_real(&a, photos);
    }
    let run = run_config_of(&a.model[0]);
    let dataset = match (&a.dataset, &run) {
        (Some(d), _) => d.clone(),
        (None, Some(r)) => r.dataset.clone(),
        (None, None) => bail!(
            "--dataset is needed: {} has no run.json naming its dataset",
            a.model[0].display()
        ),
    };
    let lpips = lpips_weights(&a.lpips)?;
    let assets = a.assets.clone().or_else(|| run.and_then(|r| r.assets));
    let catalog = load_catalog(&assets)?;
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} samples  eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let rows = evaluate(
        &a.model,
        &dataset,
        &a.split,
        catalog,
        &a.device,
        lpips.as_deref(),
        |i, n| {
            bar.set_length(n as u64);
            bar.set_position(i as u64);
        },
    )?;
    bar.finish_and_clear();
    print!("{}", table(&rows));
    if let Some(path) = &a.json {
        crate::render_cmd::ensure_parent(path, "--json")?;
        std::fs::write(path, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// `--lpips`: "none", "builtin" (which must be installed) or a weights file.
fn lpips_weights(arg: &str) -> Result<Option<PathBuf>> {
    match arg {
        "none" => Ok(None),
        "builtin" => {
            let path = lightfarm_nets::vgg::builtin_weights();
            if !path.is_file() {
                bail!(
                    "--lpips builtin: {} is not installed: {}; or pass --lpips none to \
                     evaluate without LPIPS",
                    path.display(),
                    lightfarm_nets::vgg::BUILTIN_WEIGHTS_FIX
                );
            }
            Ok(Some(path))
        }
        file => Ok(Some(PathBuf::from(file))),
    }
}
