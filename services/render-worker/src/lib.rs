//! The render worker: lease → fetch missing assets → assemble → render → outbox → upload.
//!
//! The CPU's part of a sample (assembly, environment maps, BVH builds: `sample.rs`) runs while
//! the device renders the previous one: the worker holds at most two leases, the one it renders
//! and the next, and one heartbeat (`heartbeat.rs`) keeps both alive.
//!
//! A finished sample is written to a durable outbox (EXR, then its header JSON by atomic
//! rename) before it is uploaded, so it survives a coordinator outage or a worker restart and
//! is uploaded when the coordinator answers again. Assets are cached by BLAKE3 and verified.
//! Heartbeats keep leases alive during long renders. On shutdown (SIGTERM) the worker stops
//! leasing, finishes and uploads what it holds, then exits.

mod cache;
pub mod client;
mod heartbeat;
mod outbox;
mod sample;

use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use lightfarm_proto::v1 as pb;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_scene::expand::SampleSpec;
use tokio::sync::watch;
use tracing::Instrument;

use heartbeat::{Heartbeat, HeldLeases};

pub use cache::AssetCache;
pub use client::Client;
pub use outbox::{Outbox, OutboxEntry};
pub use sample::{prepare, render_to_exr, Prepared};

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
        tracing::info!("shutdown requested: finishing the samples it holds, then exiting");
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
    let held = HeldLeases::default();
    let heartbeat = Heartbeat::start(
        client.clone(),
        reg.worker_id.clone(),
        held.clone(),
        Duration::from_secs(u64::from(reg.heartbeat_seconds.max(1))),
        stop.clone(),
    );
    let worker = Worker {
        client: &client,
        reg: &reg,
        cache: &cache,
        held: &held,
    };

    let mut done = 0u64;
    let mut idle = Duration::from_millis(200);
    let mut next: Option<Box<Leased>> = None;
    let result = loop {
        let current = match next.take() {
            Some(leased) => leased,
            None => {
                if *stop.borrow() || config.max_samples.is_some_and(|m| done >= m) {
                    break Ok(());
                }
                match worker.lease_and_prepare().await {
                    Ok(Next::Ready(leased)) => {
                        idle = Duration::from_millis(200);
                        leased
                    }
                    Ok(Next::Failed) => continue,
                    Ok(Next::Empty) => {
                        // Nothing to do: back off up to 2 s, waking early on shutdown.
                        let mut s = stop.clone();
                        let _ = tokio::time::timeout(idle, s.changed()).await;
                        idle = (idle * 2).min(Duration::from_secs(2));
                        continue;
                    }
                    Err(e) => break Err(e),
                }
            }
        };
        // The device renders this sample while the CPU leases and prepares the next (unless
        // the worker is draining or the next would pass max_samples).
        let want_next = !*stop.borrow() && config.max_samples.is_none_or(|m| done + 1 < m);
        let prefetch = async {
            if want_next {
                Some(worker.lease_and_prepare().await)
            } else {
                None
            }
        };
        let finish = async {
            let span = current.span.clone();
            let lease = current.task.lease_id.clone();
            let result = match render_leased(&renderer, &outbox, &reg.worker_id, *current).await {
                // Uploaded as soon as it is rendered, while the next one may still be prepared.
                Ok(entry) => outbox
                    .upload(&client, &entry)
                    .instrument(span)
                    .await
                    .map(|_| 1),
                Err(e) => {
                    let reason = format!("{e:#}");
                    span.in_scope(|| tracing::warn!("render failed: {reason}"));
                    if let Err(e) = client.fail(&reg.worker_id, &lease, &reason).await {
                        tracing::warn!("reporting the failure: {e:#}");
                    }
                    Ok(0)
                }
            };
            held.remove(&lease);
            result
        };
        let (finished, prefetched) = tokio::join!(finish, prefetch);
        match finished {
            Ok(n) => done += n,
            Err(e) => break Err(e),
        }
        match prefetched {
            Some(Ok(Next::Ready(leased))) => next = Some(leased),
            Some(Ok(Next::Empty | Next::Failed)) | None => {}
            Some(Err(e)) => break Err(e),
        }
    };
    // A prepared sample left over from an error is given back by its lease's expiry.
    heartbeat.end().await;
    result?;
    outbox.flush(&client).await?;
    client.leaving(&reg.worker_id).await;
    tracing::info!(samples = done, "worker stopped");
    Ok(())
}

/// What the pull loop shares with the leasing and preparing of a task.
struct Worker<'a> {
    client: &'a Client,
    reg: &'a pb::RegisterWorkerResponse,
    cache: &'a Arc<AssetCache>,
    held: &'a HeldLeases,
}

/// A leased task, prepared for the device.
struct Leased {
    task: pb::Task,
    prepared: Prepared,
    span: tracing::Span,
}

enum Next {
    Ready(Box<Leased>),
    /// The coordinator had no task.
    Empty,
    /// The task leased could not be prepared; the failure has been reported.
    Failed,
}

impl Worker<'_> {
    /// Leases one task and prepares it: its assets fetched, the sample assembled and its
    /// scene packed. Errors are the coordinator's (leasing); a task that cannot be prepared is
    /// reported as failed.
    async fn lease_and_prepare(&self) -> Result<Next> {
        let tasks = self
            .client
            .lease(&self.reg.worker_id, 1, self.cache.hashes()?)
            .await?;
        let Some(task) = tasks.into_iter().next() else {
            return Ok(Next::Empty);
        };
        self.held.add(&task.lease_id);
        let span = tracing::info_span!("task", job = %task.job_id, index = task.index);
        span.in_scope(|| tracing::info!(lease = %task.lease_id, "leased"));
        match self.prepare(&task).instrument(span.clone()).await {
            Ok(prepared) => Ok(Next::Ready(Box::new(Leased {
                task,
                prepared,
                span,
            }))),
            Err(e) => {
                let reason = format!("{e:#}");
                span.in_scope(|| tracing::warn!("preparing the sample failed: {reason}"));
                if let Err(e) = self
                    .client
                    .fail(&self.reg.worker_id, &task.lease_id, &reason)
                    .await
                {
                    tracing::warn!("reporting the failure: {e:#}");
                }
                self.held.remove(&task.lease_id);
                Ok(Next::Failed)
            }
        }
    }

    /// Fetches the task's assets and does the CPU's part of its sample.
    async fn prepare(&self, task: &pb::Task) -> Result<Prepared> {
        let catalog_hash = if task.catalog_blake3.is_empty() {
            self.reg.catalog_blake3.clone()
        } else {
            task.catalog_blake3.clone()
        };
        self.cache.ensure(self.client, &catalog_hash).await?;
        for asset in &task.assets {
            self.cache.ensure(self.client, &asset.blake3).await?;
        }
        let catalog = self
            .cache
            .materialize_catalog(&catalog_hash, &task.assets)?;
        let sample: SampleSpec =
            serde_json::from_str(&task.sample_json).context("the task's sample JSON")?;
        tokio::task::spawn_blocking(move || prepare(&catalog, &sample))
            .await
            .context("preparing thread")?
    }
}

/// Renders a prepared task on the device and writes it to the outbox.
async fn render_leased(
    renderer: &Arc<Renderer>,
    outbox: &Arc<Outbox>,
    worker: &str,
    leased: Leased,
) -> Result<OutboxEntry> {
    let Leased { task, prepared, .. } = leased;
    let (r, dir) = (renderer.clone(), outbox.clone());
    let (sample_json, job_id, index) = (task.sample_json.clone(), task.job_id.clone(), task.index);
    let (exr, stats) = tokio::task::spawn_blocking(move || -> Result<(PathBuf, String)> {
        let path = dir.exr_path(&job_id, index);
        let stats = prepared.render_to_exr(&r, &sample_json, &path)?;
        Ok((path, stats))
    })
    .await
    .context("render thread")??;
    outbox.commit_entry(&exr, worker, &task, &stats)
}
