//! Input-pipeline benchmark: samples/s the trainer's loader delivers from a folder export, with
//! no training behind it. Each draw reads a sample EXR, decodes it, crops, mirrors and pairs it
//! and looks up its HDRIs' prefiltered light maps: the work `Prefetcher` threads do ahead of
//! every step. The decoded-sample cache is off by default, as it is in effect for a dataset far
//! larger than it (the paper's 300k samples); `--cache` turns it back on (small datasets).
//!
//! cargo run --release -p lightfarm-trainer --example bench_loader -- \
//!     --dataset out/dataset-512 --batch 8 --crop 512 --threads 2 --batches 10 [--cache]
//!
//! Prints one JSON line; compare `samples_per_s` with the training step's rate
//! (`bench_train`, `bench/gpu.sh`): the loader keeps up when it is the larger.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use lightfarm_scene::Catalog;
use lightfarm_trainer::data::{Dataset, PrefetchParams, Prefetcher};
use lightfarm_trainer::lights::LightCache;

mod common;
use common::arg;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dataset: PathBuf = arg(&args, "--dataset", PathBuf::new());
    if dataset.as_os_str().is_empty() {
        return Err(
            "--dataset DIR: a folder export (`lightfarm export JOB --format folder`)".into(),
        );
    }
    let split: String = arg(&args, "--split", "all".to_string());
    let batch: usize = arg(&args, "--batch", 8);
    let crop: usize = arg(&args, "--crop", 0);
    let threads: usize = arg(&args, "--threads", 2);
    let batches: u64 = arg(&args, "--batches", 10);
    let warmup: u64 = arg(&args, "--warmup", 1);
    let cache = args.iter().any(|a| a == "--cache");

    let mut data = Dataset::open(&dataset, &split)?;
    if !cache {
        data = data.with_decoded_cache(0);
    }
    let data = Arc::new(data);
    let lights = Arc::new(LightCache::new(Catalog::builtin()?));
    let mut prefetch = Prefetcher::start(
        data.clone(),
        data.items(),
        lights,
        PrefetchParams {
            seed: 0,
            batch,
            crop,
            start: 0,
            end: warmup + batches,
            threads,
        },
    );
    // The warm-up batches pay the HDRIs' prefiltering, once per HDRI for the whole run.
    for _ in 0..warmup {
        prefetch.next_batch()?;
    }
    let t0 = Instant::now();
    let mut size = 0;
    for i in 0..batches {
        let examples = prefetch.next_batch()?;
        size = examples.first().map_or(0, |e| e.size);
        eprintln!("batch {i}: {:.2} s", t0.elapsed().as_secs_f64());
    }
    let seconds = t0.elapsed().as_secs_f64();
    println!(
        "{}",
        serde_json::json!({
            "dataset": dataset,
            "samples_in_split": data.len(),
            "batch": batch,
            "size": size,
            "threads": threads,
            "batches": batches,
            "decoded_cache": cache,
            "seconds": seconds,
            "samples_per_s": (batches as usize * batch) as f64 / seconds,
        })
    );
    Ok(())
}
