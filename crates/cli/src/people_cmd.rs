//! `lightfarm people check`: generates, dresses and renders consecutive synthetic identities
//! and checks each is a clean person (finite unit-normal geometry, eyes inside the head, no
//! skin through the garment, a finite image with the subject in it). The robustness run of
//! the README (1,000 identities) is this command.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_scene::expand::expand;
use lightfarm_scene::expand::SampleSpec;
use lightfarm_scene::identity::{identity_name, sample_identity};
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_subject::render::render_sample;
use lightfarm_subject::sanity::check_assembly;

use crate::sheet::{tiles, Sheet};

#[derive(Subcommand, Debug)]
pub enum PeopleCommand {
    /// Generate, dress and render identities START..START+COUNT and check each one.
    Check(CheckArgs),
}

#[derive(Args, Debug)]
pub struct CheckArgs {
    /// A dataset spec whose `[assets] heads` has "synthetic" (its `[identity]` and
    /// `[subject]` are used); default: every person dressed, half with an expression.
    spec: Option<PathBuf>,
    /// First identity id.
    #[arg(long, default_value_t = 0)]
    start: u64,
    /// How many consecutive identities.
    #[arg(long, default_value_t = 1000)]
    count: u64,
    /// Render size in pixels (0: check geometry only, no render).
    #[arg(long, default_value_t = 24)]
    size: u32,
    #[arg(long, default_value_t = 1)]
    spp: u32,
    /// Also write one JSON line per identity (stats, problems, seconds) here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Asset catalog (default: the built-in one, or $LIGHTFARM_ASSETS/catalog.toml).
    #[arg(long)]
    catalog: Option<PathBuf>,
    #[arg(long, env = "LIGHTFARM_DEVICE", default_value = "auto")]
    device: String,
    /// Also draw the people that failed as a contact sheet (PNG; one row each, the problem as
    /// its caption), rendered again at --sheet-size.
    #[arg(long)]
    sheet: Option<PathBuf>,
    #[arg(long, default_value_t = 192)]
    sheet_size: u32,
}

const DEFAULT_SPEC: &str = "name = \"people-check\"\nseed = 1\ncount = 1000\n\
    [assets]\nheads = [\"synthetic\"]\n\
    [subject]\ngarment_probability = 1.0\nexpression_probability = 0.5\n";

pub fn people(cmd: PeopleCommand) -> Result<()> {
    match cmd {
        PeopleCommand::Check(a) => check(a),
    }
}

/// Problems of a rendered image: NaN or negative pixels, or no subject in the mask.
fn image_problems(out: &lightfarm_render::RenderOutput) -> Vec<String> {
    let mut p = Vec::new();
    for (i, lit) in out.lit.iter().enumerate() {
        if lit.iter().flatten().any(|x| !x.is_finite() || *x < 0.0) {
            p.push(format!("lighting {i} has NaN, infinite or negative pixels"));
        }
    }
    let coverage = out.mask.iter().sum::<f32>() / out.mask.len().max(1) as f32;
    if !(0.05..=0.98).contains(&coverage) {
        p.push(format!(
            "the subject covers {:.0} % of the image",
            100.0 * coverage
        ));
    }
    p
}

fn check(args: CheckArgs) -> Result<()> {
    if args.count == 0 {
        bail!("--count must be at least 1");
    }
    if args.size > 512 || args.spp == 0 {
        bail!("--size must be 0..=512 and --spp at least 1");
    }
    let catalog = crate::spec_cmd::load_catalog(&args.catalog)?;
    let raw = match &args.spec {
        Some(p) => DatasetSpec::load(p)?,
        None => DatasetSpec::from_toml_str(DEFAULT_SPEC, "people-check (built in)")?,
    };
    let spec = raw.validate(&catalog)?;
    let Some(people) = spec.synthetic.as_ref() else {
        bail!("the spec's [assets] heads has no \"synthetic\": there are no people to check");
    };
    let renderer = if args.size > 0 {
        let device: DeviceRequest = args.device.parse().context("--device")?;
        Some(Renderer::new(&device)?)
    } else {
        None
    };
    let mut report = match &args.report {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).with_context(|| format!("--report {}", p.display()))?,
        )),
        None => None,
    };
    let bar = ProgressBar::new(args.count);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} people  eta {eta}  {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    if let Some(p) = &args.sheet {
        crate::render_cmd::ensure_parent(p, "--sheet")?;
        if !(16..=1024).contains(&args.sheet_size) {
            bail!(
                "--sheet-size {} must be in 16..=1024 pixels",
                args.sheet_size
            );
        }
    }
    // Sample k's camera, lighting and dressing, with identity k in it.
    let person_sample = |k: u64, size: u32, spp: u32| -> Result<SampleSpec> {
        let mut sample = expand(&spec, k % spec.count)?;
        sample.head.id = lightfarm_scene::identity::SYNTHETIC.to_owned();
        sample.head.blake3.clear();
        sample.identity = identity_name(k);
        sample.head.synthetic = Some(lightfarm_scene::expand::SyntheticHead {
            identity: sample_identity(&people.spec, spec.seed, k),
            models: people.models.iter().map(Into::into).collect(),
        });
        sample.render.width = size.max(1);
        sample.render.height = size.max(1);
        sample.render.spp = spp;
        Ok(sample)
    };
    let started = Instant::now();
    let (mut failed, mut assemble_s, mut render_s) = (Vec::new(), 0.0, 0.0);
    for k in args.start..args.start + args.count {
        let name = identity_name(k);
        bar.set_message(name.clone());
        let sample = person_sample(k, args.size, args.spp)?;
        let t = Instant::now();
        let mut problems = Vec::new();
        let mut stats = None;
        match lightfarm_subject::assemble(&sample, &catalog) {
            Ok(a) => {
                assemble_s += t.elapsed().as_secs_f64();
                problems.extend(check_assembly(&a));
                if let Some(r) = &renderer {
                    let t = Instant::now();
                    match render_sample(r, &a, &mut |_| {}) {
                        Ok(out) => problems.extend(image_problems(&out)),
                        Err(e) => problems.push(format!("render: {e}")),
                    }
                    render_s += t.elapsed().as_secs_f64();
                }
                stats = Some(a.stats);
            }
            Err(e) => problems.push(format!("assemble: {e}")),
        }
        if let Some(w) = report.as_mut() {
            let line = serde_json::json!({
                "identity": name, "ok": problems.is_empty(), "problems": problems,
                "stats": stats, "seconds": t.elapsed().as_secs_f64(),
            });
            // Flushed per person: a long run killed half way keeps what it checked.
            writeln!(w, "{line}")
                .and_then(|_| w.flush())
                .context("--report")?;
        }
        if !problems.is_empty() {
            bar.suspend(|| eprintln!("{name}: {}", problems.join("; ")));
            failed.push((k, name, problems.join("; ")));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let Some(mut w) = report {
        w.flush().context("--report")?;
    }
    let n = args.count as f64;
    eprintln!(
        "{} of {} people clean ({}..{}); {:.2} s per person to generate and assemble{}, {:.0} s in all",
        args.count as usize - failed.len(),
        args.count,
        args.start,
        args.start + args.count,
        assemble_s / n,
        if renderer.is_some() {
            format!(", {:.2} s to render at {}² × {} spp", render_s / n, args.size, args.spp)
        } else {
            String::new()
        },
        started.elapsed().as_secs_f64()
    );
    if let (Some(path), false) = (&args.sheet, failed.is_empty()) {
        let renderer = match renderer {
            Some(r) => r,
            None => Renderer::new(&args.device.parse().context("--device")?)?,
        };
        failure_sheet(&renderer, &catalog, &failed, path, args.sheet_size, |k| {
            person_sample(k, args.sheet_size, 16)
        })?;
    }
    if !failed.is_empty() {
        let names: Vec<&str> = failed.iter().map(|f| f.1.as_str()).collect();
        bail!(
            "{} people failed the checks: {}",
            failed.len(),
            names.join(", ")
        );
    }
    Ok(())
}

/// The failed people of a run as a contact sheet, each rendered again at `size`² × 16 spp
/// with its problems as the row's caption.
fn failure_sheet(
    renderer: &Renderer,
    catalog: &lightfarm_scene::Catalog,
    failed: &[(u64, String, String)],
    path: &std::path::Path,
    size: u32,
    sample_of: impl Fn(u64) -> Result<SampleSpec>,
) -> Result<()> {
    let mut sheet = Sheet::new(failed.len() as u32, size, size);
    for (row, (k, name, problems)) in failed.iter().enumerate() {
        let caption = format!("{name}: {problems}");
        let out = lightfarm_subject::assemble(&sample_of(*k)?, catalog)
            .map_err(anyhow::Error::from)
            .and_then(|a| render_sample(renderer, &a, &mut |_| {}).map_err(Into::into));
        match out {
            Ok(out) => sheet.row(row as u32, &caption, &tiles(&out)),
            Err(e) => sheet.failed_row(row as u32, &format!("{caption}; {e}")),
        }
    }
    let img = image::RgbImage::from_raw(sheet.width, sheet.height, sheet.pixels)
        .context("contact sheet buffer has the wrong size")?;
    img.save_with_format(path, image::ImageFormat::Png)
        .with_context(|| format!("--sheet {}", path.display()))?;
    eprintln!("{}: {} people that failed", path.display(), failed.len());
    Ok(())
}
