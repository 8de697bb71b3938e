//! `lightfarm spec …` (dataset specs) and `lightfarm assets …` (the asset catalog).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use lightfarm_scene::expand::expand_json;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;

#[derive(Subcommand, Debug)]
pub enum SpecCommand {
    /// Print the full JSON of sample INDEX of a dataset spec: every asset hash and parameter.
    /// The same (spec, index) gives the same JSON on every run and machine.
    Expand(ExpandArgs),
    /// Check a dataset spec against the asset catalog and report what it selects.
    Check(CheckArgs),
    /// Assemble sample INDEX and write its scene as one .glb: the head, hair, eyebrows and
    /// eyelashes as fibres (LINES with `_RADIUS`, the hair material in extras.lightfarm),
    /// garment, glasses, headset, the textures (PNG) and the sample's camera, for inspection in other tools or
    /// `lightfarm render`.
    Glb(GlbArgs),
}

#[derive(Args, Debug)]
pub struct GlbArgs {
    /// The dataset spec (TOML; see examples/dataset.toml).
    spec: PathBuf,
    /// Sample index, 0..count.
    #[arg(long)]
    index: u64,
    /// Output .glb.
    #[arg(long)]
    out: PathBuf,
    /// Asset catalog (default: the built-in one, or $LIGHTFARM_ASSETS/catalog.toml).
    #[arg(long)]
    catalog: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ExpandArgs {
    /// The dataset spec (TOML; see examples/dataset.toml).
    spec: PathBuf,
    /// Sample index, 0..count.
    #[arg(long)]
    index: u64,
    /// Asset catalog (default: the built-in one, or $LIGHTFARM_ASSETS/catalog.toml).
    #[arg(long)]
    catalog: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct CheckArgs {
    spec: PathBuf,
    #[arg(long)]
    catalog: Option<PathBuf>,
}

#[derive(Subcommand, Debug)]
pub enum AssetsCommand {
    /// List the catalog's assets.
    List {
        #[arg(long)]
        catalog: Option<PathBuf>,
    },
    /// Recompute every asset's BLAKE3 hash and compare it with the catalog.
    Verify {
        #[arg(long)]
        catalog: Option<PathBuf>,
    },
}

/// The catalog at `--catalog`, else the built-in one (or `$LIGHTFARM_ASSETS`).
pub(crate) fn load_catalog(path: &Option<PathBuf>) -> Result<Catalog> {
    Ok(match path {
        Some(p) => Catalog::load(p)?,
        None => Catalog::builtin()?,
    })
}

pub fn spec(cmd: SpecCommand) -> Result<()> {
    match cmd {
        SpecCommand::Expand(a) => {
            let catalog = load_catalog(&a.catalog)?;
            let spec = DatasetSpec::load(&a.spec)?.validate(&catalog)?;
            println!("{}", expand_json(&spec, a.index)?);
        }
        SpecCommand::Glb(a) => {
            let catalog = load_catalog(&a.catalog)?;
            let spec = DatasetSpec::load(&a.spec)?.validate(&catalog)?;
            let sample = lightfarm_scene::expand::expand(&spec, a.index)?;
            let mut assembled =
                lightfarm_subject::assemble(&sample, &catalog).with_context(|| {
                    format!("assembling sample {} of {}", a.index, a.spec.display())
                })?;
            assembled.scene.cameras = vec![assembled.camera];
            lightfarm_render::scene::write_glb(&assembled.scene, &a.out)?;
            let strands: usize = assembled
                .scene
                .curves
                .iter()
                .map(|c| c.strand_count())
                .sum();
            let segments: usize = assembled
                .scene
                .curves
                .iter()
                .map(|c| c.segment_count())
                .sum();
            println!(
                "{}: sample {} — {} triangles, {strands} strands ({segments} segments), camera {:?}",
                a.out.display(),
                a.index,
                assembled.scene.triangle_count(),
                assembled.camera.position
            );
        }
        SpecCommand::Check(a) => {
            let catalog = load_catalog(&a.catalog)?;
            let spec = DatasetSpec::load(&a.spec)?.validate(&catalog)?;
            let mut train: Vec<String> = spec
                .train_identities()
                .iter()
                .map(|s| s.to_string())
                .collect();
            let mut test: Vec<String> = spec
                .test_identities()
                .iter()
                .map(|s| s.to_string())
                .collect();
            if let Some(p) = &spec.synthetic {
                // Held-out ids are a hash rule, not a list: count them over a prefix.
                let scanned = p.count.min(100_000);
                let held = (0..scanned).filter(|&k| p.held_out(k)).count();
                train.push(format!("{} synthetic people (ids 0..{})", p.count, p.count));
                test.push(format!(
                    "synthetic ids held out: {held} of the first {scanned} (names {:?})",
                    p.held_out_names
                ));
            }
            if train.is_empty() {
                bail!("{}: no training identities left", a.spec.display());
            }
            println!(
                "{}: ok — train identities: {}; test identities: {}",
                a.spec.display(),
                train.join(", "),
                if test.is_empty() {
                    "none".to_string()
                } else {
                    test.join(", ")
                }
            );
        }
    }
    Ok(())
}

pub fn assets(cmd: AssetsCommand) -> Result<()> {
    match cmd {
        AssetsCommand::List { catalog } => {
            let c = load_catalog(&catalog)?;
            for a in &c.assets {
                let tags: Vec<String> = a.tags.iter().map(|(k, v)| format!("{k}={v}")).collect();
                println!(
                    "{:<28} {:<8} {:<12} {}  {}",
                    a.id,
                    format!("{:?}", a.kind).to_lowercase(),
                    a.license,
                    &a.blake3[..12],
                    tags.join(" ")
                );
            }
        }
        AssetsCommand::Verify { catalog } => {
            let c = load_catalog(&catalog)?;
            c.verify().context("asset verification failed")?;
            println!(
                "{} assets verified under {}",
                c.assets.len(),
                c.root.display()
            );
        }
    }
    Ok(())
}
