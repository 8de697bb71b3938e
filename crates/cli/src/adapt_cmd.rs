//! `lightfarm adapt`: synthetic-to-real adaptation of a trained model on real photos.

use std::path::PathBuf;

use anyhow::Result;
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
