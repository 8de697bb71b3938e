//! The render worker: lease → fetch missing assets → assemble → render → outbox → upload.
//!
//! A finished sample is written to a durable outbox (EXR, then its header JSON by atomic
//! rename) before it is uploaded, so it survives a coordinator outage or a worker restart and
//! is uploaded when the coordinator answers again. Assets are cached by BLAKE3 and verified.
//! Heartbeats keep leases alive during long renders. On shutdown (SIGTERM) the worker stops
//! leasing, finishes and uploads what it holds, then exits.

mod cache;
pub mod client;
mod outbox;

use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use lightfarm_proto::v1 as pb;
use lightfarm_render::output::write_exr;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{Renderer, RENDERER_VERSION};
use lightfarm_scene::expand::SampleSpec;
use tokio::sync::watch;

pub use cache::AssetCache;
pub use client::Client;
pub use outbox::{Outbox, OutboxEntry};

/// How a worker runs; `lightfarm serve worker` fills it from flags and env.
#[derive(Clone, Debug)]
pub struct WorkerConfig {
    /// e.g. http://coordinator:7070
    pub coordinator: String,
    pub token: String,
    /// Stable name (the host name by default): a restarted worker with the same name gets its
    /// abandoned leases requeued at once.
    pub name: String,
    /// Asset cache and outbox live here.
    pub cache_dir: PathBuf,
    pub device: String,
    /// CA certificate (PEM) for a TLS coordinator.
    pub tls_ca: Option<PathBuf>,
    /// Exit after this many samples (tests, benchmarks); None = run until shutdown.
    pub max_samples: Option<u64>,
}

/// Runs the pull loop until `shutdown` resolves (then drains) or `max_samples` are done.
pub async fn run(
    config: WorkerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<()> {
    let (stop_tx, stop) = watch::channel(false);
    tokio::spawn(async move {
        shutdown.await;
        tracing::info!("shutdown requested: finishing the current sample, then exiting");
        let _ = stop_tx.send(true);
    });
    let device: DeviceRequest = config.device.parse().context("--device")?;
    let renderer = Arc::new(
        tokio::task::spawn_blocking(move || Renderer::new(&device))
            .await
            .context("renderer thread")??,
    );
    let device_name = format!("{} ({})", renderer.device().name, renderer.device().kind);
    let cache = Arc::new(AssetCache::open(&config.cache_dir.join("assets"))?);
    let outbox = Arc::new(Outbox::open(&config.cache_dir.join("outbox"))?);
    let client = Client::connect(
        &config.coordinator,
        &config.token,
        config.tls_ca.as_deref(),
        stop.clone(),
    )
    .await?;

    // Whatever a previous run finished but could not upload goes first.
    outbox.flush(&client).await?;
    let reg = client
        .register(&config.name, &device_name, cache.hashes()?)
        .await?;
    tracing::info!(worker = %reg.worker_id, device = %device_name, lease_s = reg.lease_seconds, "registered");
    let heartbeat = Duration::from_secs(u64::from(reg.heartbeat_seconds.max(1)));

    let mut done = 0u64;
    let mut idle = Duration::from_millis(200);
    while !*stop.borrow() && config.max_samples.is_none_or(|m| done < m) {
        let tasks = client.lease(&reg.worker_id, 1, cache.hashes()?).await?;
        let Some(task) = tasks.into_iter().next() else {
            // Nothing to do: back off up to 2 s, waking early on shutdown.
            let mut s = stop.clone();
            let _ = tokio::time::timeout(idle, s.changed()).await;
            idle = (idle * 2).min(Duration::from_secs(2));
            continue;
        };
        idle = Duration::from_millis(200);
        let span = tracing::info_span!("task", job = %task.job_id, index = task.index);
        let _enter = span.enter();
        tracing::info!(lease = %task.lease_id, "leased");
        let beat = Heartbeat {
            every: heartbeat,
            stop: stop.clone(),
        };
        match render_task(&client, &reg, &renderer, &cache, &outbox, &task, beat).await {
            Ok(entry) => {
                outbox.upload(&client, &entry).await?;
                done += 1;
            }
            Err(e) => {
                let reason = format!("{e:#}");
                tracing::warn!("render failed: {reason}");
                if let Err(e) = client.fail(&reg.worker_id, &task.lease_id, &reason).await {
                    tracing::warn!("reporting the failure: {e:#}");
                }
            }
        }
    }
    outbox.flush(&client).await?;
    client.leaving(&reg.worker_id).await;
    tracing::info!(samples = done, "worker stopped");
    Ok(())
}

/// Renders `sample` (whose JSON is `sample_json`) and writes the sample EXR to `path`;
/// returns the render statistics as JSON. The EXR has one header attribute (renderer, sample
/// and the assembled scene's materials), so its bytes are a pure function of the sample and
/// the device: render times go to the index, not the file, and a re-render is bit-identical.
/// Besides the render's own statistics, the JSON says where the sample's time went, in
/// seconds: `assemble_seconds` (the subject: head, hair growth, garment, textures),
/// `setup_seconds` (environment maps, BVH builds, upload), the render's `seconds` (and
/// `olat_seconds`), `write_seconds` (the EXR) and `sample_seconds` (all of it).
pub fn render_to_exr(
    renderer: &Renderer,
    catalog: &lightfarm_scene::Catalog,
    sample: &SampleSpec,
    sample_json: &str,
    path: &std::path::Path,
) -> Result<String> {
    let start = Instant::now();
    let assembled = lightfarm_subject::assemble(sample, catalog)?;
    let assembled_at = start.elapsed().as_secs_f64();
    let out = lightfarm_subject::render::render_sample(renderer, &assembled, &mut |_| {})?;
    let rendered_at = start.elapsed().as_secs_f64();
    let meta = serde_json::json!({
        "renderer": RENDERER_VERSION,
        "sample": serde_json::from_str::<serde_json::Value>(sample_json)?,
        // Every material of the assembled scene (models, classes, all parameters).
        "materials": lightfarm_render::scene::materials_json(&assembled.scene),
        // What the id pass's values mean (here, not as a second attribute: see id_table_json).
        "id_table": serde_json::from_str::<serde_json::Value>(&lightfarm_render::output::id_table_json())?,
    });
    write_exr(
        path,
        &out,
        &[("lightfarm.sample".to_string(), meta.to_string())],
    )?;
    let done_at = start.elapsed().as_secs_f64();
    let mut stats = serde_json::to_value(&out.stats)?;
    let render_seconds = out.stats.seconds + out.stats.olat_seconds;
    stats["assemble_seconds"] = serde_json::json!(assembled_at);
    stats["setup_seconds"] =
        serde_json::json!((rendered_at - assembled_at - render_seconds).max(0.0));
    stats["write_seconds"] = serde_json::json!(done_at - rendered_at);
    stats["sample_seconds"] = serde_json::json!(done_at);
    Ok(stats.to_string())
}

/// How often a rendering worker heartbeats, and its shutdown flag (a heartbeat says draining).
struct Heartbeat {
    every: Duration,
    stop: watch::Receiver<bool>,
}

/// Fetches the task's assets, renders it while heartbeating, and writes it to the outbox.
async fn render_task(
    client: &Client,
    reg: &pb::RegisterWorkerResponse,
    renderer: &Arc<Renderer>,
    cache: &Arc<AssetCache>,
    outbox: &Arc<Outbox>,
    task: &pb::Task,
    heartbeat: Heartbeat,
) -> Result<OutboxEntry> {
    let catalog_hash = if task.catalog_blake3.is_empty() {
        reg.catalog_blake3.clone()
    } else {
        task.catalog_blake3.clone()
    };
    cache.ensure(client, &catalog_hash).await?;
    for asset in &task.assets {
        cache.ensure(client, &asset.blake3).await?;
    }
    let catalog = cache.materialize_catalog(&catalog_hash, &task.assets)?;
    let sample: SampleSpec =
        serde_json::from_str(&task.sample_json).context("the task's sample JSON")?;

    // Heartbeats until the render is done.
    let (hb_stop, mut hb_rx) = watch::channel(false);
    let hb_client = client.clone();
    let (worker, lease) = (reg.worker_id.clone(), task.lease_id.clone());
    let Heartbeat { every, mut stop } = heartbeat;
    let hb = tokio::spawn(async move {
        let mut draining = *stop.borrow();
        loop {
            tokio::select! {
                _ = tokio::time::sleep(every) => {}
                _ = hb_rx.changed() => return,
                // A shutdown request is told at once (the dashboard shows "draining").
                _ = stop.changed(), if !draining => draining = true,
            }
            match hb_client
                .heartbeat(&worker, std::slice::from_ref(&lease))
                .await
            {
                Ok(lost) if lost.contains(&lease) => {
                    tracing::warn!(lease = %lease, "lease lost while rendering; the result will be offered anyway");
                }
                Ok(_) => {}
                Err(e) => tracing::warn!("heartbeat: {e:#}"),
            }
        }
    });

    let (r, sample_json, dir) = (renderer.clone(), task.sample_json.clone(), outbox.clone());
    let (job_id, index) = (task.job_id.clone(), task.index);
    let rendered = tokio::task::spawn_blocking(move || -> Result<(PathBuf, String)> {
        let path = dir.exr_path(&job_id, index);
        let stats = render_to_exr(&r, &catalog, &sample, &sample_json, &path)?;
        Ok((path, stats))
    })
    .await;
    let _ = hb_stop.send(true);
    let _ = hb.await;
    let (exr, stats) = rendered.context("render thread")??;
    outbox.commit_entry(&exr, &reg.worker_id, task, &stats)
}
