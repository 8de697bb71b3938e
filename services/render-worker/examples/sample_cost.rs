//! What one dataset sample costs a render worker: samples FIRST..FIRST+COUNT of a spec, each
//! through `render_to_exr`, the function the worker runs per leased task (assembly of the
//! subject, the environment maps, the BVHs, both lightings on shared paths with every pass of
//! the spec, the EXR written to disk). Issue 15's GPU target is this wall time at the spec's
//! own 512², 256 spp: at most 1 s a sample.
//!
//! ```text
//! cargo run --release -p lightfarm-worker --example sample_cost -- SPEC FIRST COUNT [SIZE SPP] [--device D]
//! ```
//!
//! SIZE and SPP override the spec's (a square image). `--device` is `auto` (the default), `gpu`,
//! `cpu`, an index or part of a name, as for `lightfarm render`. One untimed render of sample
//! FIRST at 16², 1 spp runs first, so the kernel compile and the catalog's loads are not counted
//! against the first sample. Prints a markdown table for BENCHMARKS.md, one row per sample, then
//! the median, min and max. The last column is the start of each sample EXR's BLAKE3: a
//! change meant only to make samples faster must leave it as it was. Then the same samples
//! again as a worker's loop runs them, the next one prepared (assembly, maps, BVHs) on another
//! thread while the device renders the current one, and the samples/s of both ways (the
//! overlapped EXRs must be the same bytes).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_scene::expand::{expand, SampleSpec};
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;
use lightfarm_worker::{prepare, render_to_exr, Prepared};

const USAGE: &str = "usage: sample_cost SPEC FIRST COUNT [SIZE SPP] [--device D]";

struct Args {
    spec: PathBuf,
    first: u64,
    count: u64,
    size_spp: Option<(u32, u32)>,
    device: DeviceRequest,
}

fn parse_args() -> Result<Args> {
    let mut positional = Vec::new();
    let mut device = DeviceRequest::Auto;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        if a == "--device" {
            let d = it
                .next()
                .context("--device needs a value (auto, gpu, cpu, an index or a name)")?;
            device = d.parse().with_context(|| format!("--device {d}"))?;
        } else {
            positional.push(a);
        }
    }
    let num = |i: usize, what: &str| -> Result<u64> {
        positional[i]
            .parse()
            .with_context(|| format!("{what} '{}' is not a whole number ({USAGE})", positional[i]))
    };
    let size_spp = match positional.len() {
        3 => None,
        5 => {
            let (size, spp) = (num(3, "SIZE")?, num(4, "SPP")?);
            if size == 0 || spp == 0 || size > 16384 || spp > 1 << 20 {
                bail!("SIZE must be 1..=16384 and SPP 1..=1048576, not {size} and {spp}");
            }
            Some((size as u32, spp as u32))
        }
        _ => bail!("{USAGE}"),
    };
    Ok(Args {
        spec: PathBuf::from(&positional[0]),
        first: num(1, "FIRST")?,
        count: num(2, "COUNT")?.max(1),
        size_spp,
        device,
    })
}

fn sized(mut sample: SampleSpec, size: u32, spp: u32) -> SampleSpec {
    sample.render.width = size;
    sample.render.height = size;
    sample.render.spp = spp;
    sample
}

fn main() -> Result<()> {
    let args = parse_args()?;
    let catalog = Catalog::builtin()?;
    let spec = DatasetSpec::load(&args.spec)
        .with_context(|| format!("spec {}", args.spec.display()))?
        .validate(&catalog)
        .with_context(|| format!("spec {}", args.spec.display()))?;
    let renderer = Renderer::new(&args.device)?;
    let dir = tempfile::tempdir()?;
    let exr = dir.path().join("sample.exr");

    let warm = sized(expand(&spec, args.first)?, 16, 1);
    render_to_exr(
        &renderer,
        &catalog,
        &warm,
        &serde_json::to_string(&warm)?,
        &exr,
    )
    .context("warm-up render")?;

    println!("device: {}", renderer.device().name);
    println!(
        "| sample | size, spp | triangles | fibre segments | assemble s | setup s (maps, BVH, upload) | render s | EXR s | sample s | EXR BLAKE3 |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut walls = Vec::new();
    let mut hashes = Vec::new();
    let sample_of = |index: u64| -> Result<SampleSpec> {
        let sample = expand(&spec, index)?;
        Ok(match args.size_spp {
            Some((size, spp)) => sized(sample, size, spp),
            None => sample,
        })
    };
    let one_by_one = Instant::now();
    for index in args.first..args.first + args.count {
        let sample = sample_of(index)?;
        let json = serde_json::to_string(&sample)?;
        let stats = render_to_exr(&renderer, &catalog, &sample, &json, &exr)
            .with_context(|| format!("sample {index}"))?;
        let stats: serde_json::Value = serde_json::from_str(&stats)?;
        let int = |k: &str| stats.get(k).and_then(|v| v.as_u64()).unwrap_or(0);
        let secs = |k: &str| stats.get(k).and_then(|v| v.as_f64()).unwrap_or(f64::NAN);
        let render = secs("seconds") + secs("olat_seconds");
        // The file's hash, so that a change meant only to be faster can show the same bytes.
        let hash = blake3::hash(&std::fs::read(&exr)?).to_hex();
        println!(
            "| {index} | {}², {} | {} | {} | {:.3} | {:.3} | {render:.3} | {:.3} | {:.3} | {} |",
            sample.render.width,
            sample.render.spp,
            int("triangles"),
            int("curve_segments"),
            secs("assemble_seconds"),
            secs("setup_seconds"),
            secs("write_seconds"),
            secs("sample_seconds"),
            &hash[..16],
        );
        walls.push(secs("sample_seconds"));
        hashes.push(hash);
    }
    let one_by_one = one_by_one.elapsed().as_secs_f64();
    walls.sort_by(f64::total_cmp);
    let n = walls.len();
    let median = (walls[(n - 1) / 2] + walls[n / 2]) / 2.0;
    println!(
        "\nsample s over {} samples: median {median:.3}, min {:.3}, max {:.3}",
        n,
        walls[0],
        walls[n - 1]
    );

    // The same samples as the worker's loop runs them: the next one prepared (assembly, maps,
    // BVHs) on another thread while this one renders, one sample ahead at most.
    let overlapped = Instant::now();
    let (tx, rx) = std::sync::mpsc::sync_channel::<Result<(SampleSpec, Prepared)>>(0);
    let same = std::thread::scope(|scope| -> Result<bool> {
        scope.spawn(|| {
            for index in args.first..args.first + args.count {
                let prepared =
                    sample_of(index).and_then(|s| Ok((s.clone(), prepare(&catalog, &s)?)));
                if tx.send(prepared).is_err() {
                    return;
                }
            }
        });
        let mut same = true;
        for hash in &hashes {
            let (sample, prepared) = rx.recv().context("the preparing thread stopped")??;
            prepared.render_to_exr(&renderer, &serde_json::to_string(&sample)?, &exr)?;
            same &= blake3::hash(&std::fs::read(&exr)?).to_hex() == *hash;
        }
        Ok(same)
    })?;
    let overlapped = overlapped.elapsed().as_secs_f64();
    let count = args.count as f64;
    println!();
    println!(
        "{} samples one after another: {one_by_one:.3} s ({:.3} samples/s); the next prepared \
         during each render, as a worker runs them: {overlapped:.3} s ({:.3} samples/s), {:.2}x; \
         EXRs {}",
        args.count,
        count / one_by_one,
        count / overlapped,
        one_by_one / overlapped,
        if same { "identical" } else { "DIFFER" }
    );
    if !same {
        bail!("the overlapped samples' EXRs differ from the ones rendered one by one");
    }
    Ok(())
}
