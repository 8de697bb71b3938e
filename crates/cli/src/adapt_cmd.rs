//! `lightfarm adapt`: synthetic-to-real adaptation of a trained model on real photos.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_trainer::adapt::{adapt, AdaptConfig, AdaptLog, AdaptObserver};

use crate::spec_cmd::load_catalog;

#[derive(Args, Debug)]
pub struct AdaptArgs {
    /// Adaptation config (TOML): base model, photos folder, out, steps, batch, size, target,
    /// weights (examples/adapt.toml).
    pub config: PathBuf,
    /// Override `steps` (resuming a finished run to a larger count continues it).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Override `device`: auto, cpu or gpu.
    #[arg(long, env = "LIGHTFARM_TRAIN_DEVICE")]
    pub device: Option<String>,
    /// Submit to a trainer service (`lightfarm serve trainer`) instead of adapting here, and
    /// follow the job; the base is then a train job of that service (--base-job), the photos
    /// a folder under its --datasets, and the config's `base`/`out` are ignored.
    #[arg(long, env = "LIGHTFARM_TRAINER")]
    pub trainer: Option<String>,
    /// The trainer's train job whose final model to adapt (`lightfarm train-jobs`).
    #[arg(long, requires = "trainer")]
    pub base_job: Option<String>,
    /// Photo folder under the trainer's --datasets (overrides the config's `photos`).
    #[arg(long, requires = "trainer")]
    pub photos: Option<String>,
    /// Bearer token of the trainer service.
    #[arg(long, env = "LIGHTFARM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

struct Bar(ProgressBar);

impl AdaptObserver for Bar {
    fn on_start(&mut self, start: u64, end: u64) {
        self.0.set_length(end);
        self.0.set_position(start);
        self.0.reset_eta();
    }

    fn on_step(&mut self, l: &AdaptLog) {
        self.0.set_position(l.step);
        let term = |name: &str, v: Option<f32>| v.map(|v| format!(" {name} {v:.4}"));
        let terms: String = [
            term("olat", l.olat),
            term("relative", l.relative),
            term("similarity", l.similarity),
            term("gan", l.gan),
        ]
        .into_iter()
        .flatten()
        .collect();
        self.0.set_message(format!(
            "loss {:.4} ({}) {:.1} photos/s, {} photos skipped",
            l.total,
            terms.trim(),
            l.photos_per_second,
            l.skipped_photos
        ));
    }
}

pub fn run(a: AdaptArgs) -> Result<()> {
    if let Some(url) = a.trainer.clone() {
        return crate::farm_cmd::runtime()?.block_on(remote_adapt(url, a));
    }
    let mut cfg = AdaptConfig::load(&a.config)?;
    if let Some(s) = a.steps {
        cfg.steps = s;
    }
    if let Some(d) = a.device {
        cfg.device = d;
    }
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.config.display()))?;
    let catalog = load_catalog(&cfg.assets)?;
    let cancel = crate::train_cmd::cancel_on_signal()?;
    let bar = ProgressBar::new(cfg.steps).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps  eta {eta}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut observer = Bar(bar.clone());
    let s = adapt(&cfg, catalog, &mut observer, &cancel)?;
    bar.finish();
    println!(
        "{} steps {}..{} on {} photos ({} skipped, named in the log); adapted model {}; loss \
         curve {}",
        if s.cancelled { "stopped at" } else { "adapted" },
        s.start_step,
        s.end_step,
        s.photos,
        s.skipped_photos,
        s.checkpoint.display(),
        cfg.out.join(lightfarm_trainer::train::LOSS_FILE).display()
    );
    Ok(())
}

/// Submits the config to a trainer service as an adaptation of one of its train jobs and
/// follows the job to its end.
async fn remote_adapt(url: String, a: AdaptArgs) -> Result<()> {
    use lightfarm_proto::v1 as pb;
    let text = std::fs::read_to_string(&a.config)
        .with_context(|| format!("reading {}", a.config.display()))?;
    let base_job_id = a
        .base_job
        .context("--base-job: name the trainer's train job to adapt (lightfarm train-jobs)")?;
    let mut client = crate::remote_job::connect(&url, a.token)?;
    let job = client
        .submit_adapt_job(pb::SubmitAdaptJobRequest {
            config_toml: text,
            base_job_id,
            photos: a.photos.unwrap_or_default(),
            steps: a.steps.unwrap_or(0),
        })
        .await
        .map_err(|s| anyhow::anyhow!("--trainer {url}: {}", s.message()))?
        .into_inner();
    crate::remote_job::follow(&mut client, job, |l| {
        format!(
            "loss {:.4} (olat {:.4}, relative {:.4}) {:.1} photos/s, {} photos skipped",
            l.total, l.olat, l.relative, l.samples_per_second, l.skipped_photos
        )
    })
    .await
}
