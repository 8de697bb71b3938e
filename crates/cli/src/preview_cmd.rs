//! `lightfarm preview`: renders a few samples of a dataset spec small and fast, and writes a
//! labelled contact sheet so a person can check the subjects look right.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_scene::expand::{expand, SampleSpec};
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_subject::render::render_sample;

use crate::sheet::{tiles, Sheet};

#[derive(Args, Debug)]
pub struct PreviewArgs {
    /// The dataset spec (TOML; see examples/dataset.toml).
    spec: PathBuf,
    /// How many samples (rows), starting at --start.
    #[arg(long, default_value_t = 16)]
    count: u64,
    /// First sample index.
    #[arg(long, default_value_t = 0)]
    start: u64,
    /// Tile size in pixels (the spec's resolution is replaced; the camera is not).
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// Samples per pixel per lighting (the spec's spp is replaced).
    #[arg(long, default_value_t = 32)]
    spp: u32,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Asset catalog (default: the built-in one, or $LIGHTFARM_ASSETS/catalog.toml).
    #[arg(long)]
    catalog: Option<PathBuf>,
    #[arg(long, env = "LIGHTFARM_DEVICE", default_value = "auto")]
    device: String,
}

fn caption(s: &SampleSpec) -> String {
    let mut parts = vec![
        format!("#{} {}", s.index, s.head.id),
        s.head.expression.name.clone(),
        format!("hair {}", s.hair.style),
    ];
    if let Some(g) = &s.glasses {
        parts.push(g.id.clone());
    }
    if let Some(h) = &s.headset {
        parts.push(h.id.clone());
    }
    parts.push(format!("{}|{}", s.lighting[0].hdri, s.lighting[1].hdri));
    parts.join(" ")
}

pub fn run(args: PreviewArgs) -> Result<()> {
    if args.count == 0 || args.count > 256 {
        bail!(
            "--count {} must be in 1..=256 (one row per sample)",
            args.count
        );
    }
    if args.size == 0 || args.size > 1024 {
        bail!("--size {} must be in 1..=1024 pixels", args.size);
    }
    if args.spp == 0 || args.spp > 65536 {
        bail!("--spp {} must be in 1..=65536", args.spp);
    }
    crate::render_cmd::ensure_parent(&args.out, "--out")?;
    let catalog = crate::spec_cmd::load_catalog(&args.catalog)?;
    let spec = DatasetSpec::load(&args.spec)?.validate(&catalog)?;
    let end = args
        .start
        .checked_add(args.count)
        .filter(|e| *e <= spec.count);
    let Some(end) = end else {
        bail!(
            "--start {} --count {} runs past the dataset's {} samples",
            args.start,
            args.count,
            spec.count
        );
    };
    let device: DeviceRequest = args.device.parse().context("--device")?;
    let renderer = Renderer::new(&device)?;

    let bar = ProgressBar::new(args.count);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} samples  eta {eta}  {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut sheet = Sheet::new(args.count as u32, args.size, args.size);
    let mut failures = 0;
    for (row, index) in (args.start..end).enumerate() {
        let mut sample = expand(&spec, index)?;
        sample.render.width = args.size;
        sample.render.height = args.size;
        sample.render.spp = args.spp;
        bar.set_message(format!("#{index}"));
        // A bad sample is shown on the sheet (red caption) and reported, so one broken asset
        // does not hide what the other samples look like.
        let result = lightfarm_subject::assemble(&sample, &catalog)
            .and_then(|a| render_sample(&renderer, &a, &mut |_| {}));
        match result {
            Ok(out) => sheet.row(row as u32, &caption(&sample), &tiles(&out)),
            Err(e) => {
                failures += 1;
                bar.suspend(|| eprintln!("sample {index}: {e}"));
                sheet.failed_row(row as u32, &format!("#{index} FAILED: {e}"));
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let img = image::RgbImage::from_raw(sheet.width, sheet.height, sheet.pixels)
        .context("contact sheet buffer has the wrong size")?;
    img.save_with_format(&args.out, image::ImageFormat::Png)
        .with_context(|| format!("--out {}", args.out.display()))?;
    eprintln!(
        "{}: {} samples ({}..{}) at {}x{} x {} spp",
        args.out.display(),
        args.count,
        args.start,
        end,
        args.size,
        args.size,
        args.spp
    );
    if failures > 0 {
        bail!(
            "{failures} of {} samples failed (see above and the red rows of the sheet)",
            args.count
        );
    }
    Ok(())
}
