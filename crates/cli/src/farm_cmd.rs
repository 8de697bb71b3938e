//! The farm commands: `serve coordinator|worker`, `submit`, `watch`, `jobs`, `samples`,
//! `export`.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_coordinator::service::SampleAssembler;
use lightfarm_proto::v1 as pb;
use lightfarm_worker::client::{channel, AuthedChannel};

pub const DEFAULT_COORDINATOR: &str = "http://127.0.0.1:7070";

#[derive(Args, Debug, Clone)]
pub struct Connect {
    /// Coordinator address.
    #[arg(long, env = "LIGHTFARM_COORDINATOR", default_value = DEFAULT_COORDINATOR)]
    pub coordinator: String,
    /// Bearer token the coordinator was started with.
    #[arg(long, env = "LIGHTFARM_TOKEN", hide_env_values = true)]
    pub token: String,
    /// CA certificate (PEM) when the coordinator serves TLS.
    #[arg(long)]
    pub tls_ca: Option<PathBuf>,
}

#[derive(Subcommand, Debug)]
pub enum Serve {
    /// The coordinator: jobs, leases, the sample store (gRPC) and /metrics (Prometheus).
    Coordinator(CoordinatorArgs),
    /// A render worker: pulls samples from the coordinator and renders them.
    Worker(WorkerArgs),
    /// The trainer: train jobs on folder exports, checkpoints, relighting (gRPC).
    Trainer(TrainerArgs),
}

#[derive(Args, Debug)]
pub struct TrainerArgs {
    /// Job records and run directories; unfinished jobs resume from here after a restart.
    #[arg(
        long,
        env = "LIGHTFARM_TRAINER_DATA",
        default_value = "lightfarm-trainer"
    )]
    pub data: PathBuf,
    /// Directory holding folder exports; jobs name datasets relative to it.
    #[arg(long, env = "LIGHTFARM_DATASETS", default_value = ".")]
    pub datasets: PathBuf,
    #[arg(long, env = "LIGHTFARM_TRAINER_LISTEN", default_value = "0.0.0.0:7071")]
    pub listen: String,
    #[arg(long, env = "LIGHTFARM_TOKEN", hide_env_values = true)]
    pub token: String,
    /// Asset catalog the datasets were rendered from (default: the built-in one).
    #[arg(long)]
    pub catalog: Option<PathBuf>,
    /// auto, cpu or gpu.
    #[arg(long, env = "LIGHTFARM_TRAIN_DEVICE", default_value = "auto")]
    pub device: String,
    /// Bearer token of the coordinators that `farm://HOST:PORT/JOB` datasets name (default:
    /// this trainer's --token, as in a cluster sharing one).
    #[arg(long, env = "LIGHTFARM_COORDINATOR_TOKEN", hide_env_values = true)]
    pub coordinator_token: Option<String>,
}

#[derive(Args, Debug)]
pub struct CoordinatorArgs {
    /// Data directory (sled db + blobs); everything in it survives restarts.
    #[arg(long, env = "LIGHTFARM_DATA", default_value = "lightfarm-data")]
    pub data: PathBuf,
    #[arg(long, env = "LIGHTFARM_LISTEN", default_value = "0.0.0.0:7070")]
    pub listen: String,
    /// Prometheus endpoint (GET /metrics, open) and the web dashboard (`/`, behind a login
    /// with --token), HTTPS with the gRPC certificate when --tls-cert is given; "off" to
    /// disable both.
    #[arg(long, env = "LIGHTFARM_METRICS_LISTEN", default_value = "0.0.0.0:9090")]
    pub metrics_listen: String,
    /// Serve the web dashboard on the metrics port.
    #[arg(long, env = "LIGHTFARM_DASHBOARD", default_value_t = true, action = clap::ArgAction::Set)]
    pub dashboard: bool,
    #[arg(long, env = "LIGHTFARM_TOKEN", hide_env_values = true)]
    pub token: String,
    /// Lease length; a worker silent for this long loses its tasks.
    #[arg(long, env = "LIGHTFARM_LEASE_SECONDS", default_value_t = 60)]
    pub lease_seconds: u32,
    #[arg(long, env = "LIGHTFARM_MAX_UPLOAD_MB", default_value_t = 256)]
    pub max_upload_mb: u64,
    /// Asset catalog (default: the built-in one, or $LIGHTFARM_ASSETS/catalog.toml).
    #[arg(long)]
    pub catalog: Option<PathBuf>,
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// The trainer service the dashboard shows (jobs, loss curves, validation relights).
    #[arg(long, env = "LIGHTFARM_TRAINER")]
    pub trainer: Option<String>,
    /// The trainer's bearer token (default: this coordinator's --token).
    #[arg(long, env = "LIGHTFARM_TRAINER_TOKEN", hide_env_values = true)]
    pub trainer_token: Option<String>,
    /// CA certificate (PEM) of a TLS trainer.
    #[arg(long, env = "LIGHTFARM_TRAINER_CA")]
    pub trainer_ca: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct WorkerArgs {
    #[command(flatten)]
    pub connect: Connect,
    /// Worker name, stable across restarts (default: the host name).
    #[arg(long, env = "LIGHTFARM_WORKER_NAME")]
    pub name: Option<String>,
    /// Asset cache and outbox.
    #[arg(long, env = "LIGHTFARM_CACHE")]
    pub cache: Option<PathBuf>,
    #[arg(long, env = "LIGHTFARM_DEVICE", default_value = "auto")]
    pub device: String,
    /// Exit after this many samples.
    #[arg(long)]
    pub max_samples: Option<u64>,
}

#[derive(Args, Debug)]
pub struct SubmitArgs {
    pub spec: PathBuf,
    #[arg(long, default_value_t = 0)]
    pub priority: i32,
    #[command(flatten)]
    pub connect: Connect,
}

#[derive(Args, Debug)]
pub struct JobArgs {
    pub job: String,
    #[command(flatten)]
    pub connect: Connect,
}

#[derive(Args, Debug)]
pub struct JobsArgs {
    #[command(flatten)]
    pub connect: Connect,
}

#[derive(Args, Debug)]
pub struct SamplesArgs {
    #[arg(long)]
    pub job: Option<String>,
    #[arg(long)]
    pub split: Option<String>,
    #[arg(long, default_value_t = 50)]
    pub limit: u32,
    #[command(flatten)]
    pub connect: Connect,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum Format {
    Webdataset,
    Folder,
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    pub job: String,
    #[arg(long, value_enum, default_value = "webdataset")]
    pub format: Format,
    #[arg(long)]
    pub out: PathBuf,
    /// Samples per WebDataset shard.
    #[arg(long, default_value_t = 1000)]
    pub shard_size: usize,
    #[command(flatten)]
    pub connect: Connect,
}

pub fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// Resolves on Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(s) => s,
                Err(_) => {
                    let _ = ctrl_c.await;
                    return;
                }
            };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    {
        let _ = ctrl_c.await;
    }
}

pub fn serve(cmd: Serve) -> Result<()> {
    let rt = runtime()?;
    match cmd {
        Serve::Coordinator(a) => rt.block_on(serve_coordinator(a)),
        Serve::Worker(a) => rt.block_on(serve_worker(a)),
        Serve::Trainer(a) => rt.block_on(serve_trainer(a)),
    }
}

async fn serve_trainer(a: TrainerArgs) -> Result<()> {
    let catalog = crate::spec_cmd::load_catalog(&a.catalog)?;
    let svc = lightfarm_trainer::service::TrainerService::open(
        lightfarm_trainer::service::ServiceConfig {
            data: a.data.clone(),
            datasets: a.datasets.clone(),
            catalog,
            device: a.device.clone(),
            coordinator_token: a
                .coordinator_token
                .clone()
                .or_else(|| Some(a.token.clone())),
        },
    )?;
    let listener = tokio::net::TcpListener::bind(&a.listen)
        .await
        .with_context(|| format!("--listen {}: cannot bind", a.listen))?;
    tracing::info!(listen = %a.listen, data = %a.data.display(), "trainer serving");
    svc.serve(listener, &a.token, shutdown_signal()).await?;
    Ok(())
}

async fn serve_coordinator(a: CoordinatorArgs) -> Result<()> {
    let catalog = crate::spec_cmd::load_catalog(&a.catalog)?;
    let mut config =
        lightfarm_coordinator::CoordinatorConfig::new(a.data.clone(), a.token.clone(), catalog);
    config.lease_seconds = f64::from(a.lease_seconds.max(1));
    config.heartbeat_seconds = (a.lease_seconds / 4).max(1);
    config.max_upload_bytes = a.max_upload_mb.max(1) << 20;
    config.tls = a.tls_cert.clone().zip(a.tls_key.clone());
    let coordinator =
        tokio::task::spawn_blocking(move || lightfarm_coordinator::Coordinator::open(config))
            .await
            .context("opening the coordinator")??;
    let listener = tokio::net::TcpListener::bind(&a.listen)
        .await
        .with_context(|| format!("--listen {}: cannot bind", a.listen))?;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    if a.metrics_listen != "off" {
        let ml = tokio::net::TcpListener::bind(&a.metrics_listen)
            .await
            .with_context(|| format!("--metrics-listen {}: cannot bind", a.metrics_listen))?;
        let (m, s) = (
            coordinator.metrics().clone(),
            coordinator.scheduler().clone(),
        );
        let trainer = a
            .trainer
            .clone()
            .map(|url| lightfarm_coordinator::dashboard::TrainerLink {
                url,
                token: a.trainer_token.clone().unwrap_or_else(|| a.token.clone()),
                tls_ca: a.trainer_ca.clone(),
            });
        let board = a
            .dashboard
            .then(|| {
                coordinator.dashboard(&lightfarm_coordinator::dashboard::DashboardConfig {
                    token: a.token.clone(),
                    // With TLS the port is HTTPS; the session cookie only ever travels over it.
                    secure_cookies: a.tls_cert.is_some(),
                    trainer,
                })
            })
            .transpose()?;
        let tls = coordinator.metrics_tls()?;
        let mut rx = stop_rx.clone();
        tokio::spawn(async move {
            let stop = async move {
                let _ = rx.changed().await;
            };
            if let Err(e) =
                lightfarm_coordinator::metrics::serve_metrics(ml, m, s, board, tls, stop).await
            {
                tracing::error!("metrics endpoint: {e}");
            }
        });
    }
    eprintln!(
        "coordinator: gRPC on {} (data {}), metrics and dashboard on {}{}",
        listener
            .local_addr()
            .map(|a| a.to_string())
            .unwrap_or_default(),
        a.data.display(),
        if a.tls_cert.is_some() {
            "https://"
        } else {
            "http://"
        },
        a.metrics_listen
    );
    let shutdown = async move {
        shutdown_signal().await;
        let _ = stop_tx.send(true);
    };
    coordinator.serve(listener, shutdown).await?;
    Ok(())
}

fn default_cache() -> PathBuf {
    std::env::var_os("HOME")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("."))
        .join(".cache/lightfarm-worker")
}

fn hostname() -> String {
    std::fs::read_to_string("/etc/hostname")
        .ok()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| format!("worker-{}", std::process::id()))
}

async fn serve_worker(a: WorkerArgs) -> Result<()> {
    let config = lightfarm_worker::WorkerConfig {
        coordinator: a.connect.coordinator,
        token: a.connect.token,
        name: a.name.unwrap_or_else(hostname),
        cache_dir: a.cache.unwrap_or_else(default_cache),
        device: a.device,
        tls_ca: a.connect.tls_ca,
        max_samples: a.max_samples,
    };
    lightfarm_worker::run(config, shutdown_signal()).await
}

// ------------------------------------------------------------------ clients

/// Clients on a lazily connected channel carrying the token (call inside the runtime).
fn jobs_client(c: &Connect) -> Result<pb::jobs_client::JobsClient<AuthedChannel>> {
    let (ch, auth) = channel(&c.coordinator, &c.token, c.tls_ca.as_deref())?;
    Ok(pb::jobs_client::JobsClient::with_interceptor(ch, auth))
}

fn samples_client(c: &Connect) -> Result<pb::samples_client::SamplesClient<AuthedChannel>> {
    let (ch, auth) = channel(&c.coordinator, &c.token, c.tls_ca.as_deref())?;
    Ok(
        pb::samples_client::SamplesClient::with_interceptor(ch, auth)
            .max_decoding_message_size(64 << 20),
    )
}

fn status_err(c: &Connect, s: tonic::Status) -> anyhow::Error {
    if lightfarm_worker::client::transient(&s) {
        anyhow::anyhow!("cannot reach the coordinator at {} ({}): is it running? (--coordinator / LIGHTFARM_COORDINATOR)", c.coordinator, s.message())
    } else {
        anyhow::anyhow!("{}", s.message())
    }
}

fn state_name(state: i32) -> &'static str {
    match pb::JobState::try_from(state).unwrap_or(pb::JobState::Unspecified) {
        pb::JobState::Running => "running",
        pb::JobState::Paused => "paused",
        pb::JobState::Cancelled => "cancelled",
        pb::JobState::Completed => "completed",
        pb::JobState::Failed => "failed",
        pb::JobState::Unspecified => "?",
    }
}

pub fn submit(a: SubmitArgs) -> Result<()> {
    let text = std::fs::read_to_string(&a.spec)
        .with_context(|| format!("reading {}", a.spec.display()))?;
    runtime()?.block_on(async {
        let mut c = jobs_client(&a.connect)?;
        let job = c
            .submit_dataset(pb::SubmitDatasetRequest {
                spec: Some(pb::submit_dataset_request::Spec::Toml(text)),
                priority: a.priority,
            })
            .await
            .map_err(|s| status_err(&a.connect, s))
            .with_context(|| format!("submitting {}", a.spec.display()))?
            .into_inner();
        println!("{}", job.id);
        eprintln!(
            "submitted {} ({} samples); follow it with: lightfarm watch {}",
            job.id, job.count, job.id
        );
        Ok(())
    })
}

pub fn watch(a: JobArgs) -> Result<()> {
    runtime()?.block_on(async {
        let mut c = jobs_client(&a.connect)?;
        let mut stream = c
            .watch_job(pb::JobRef {
                job_id: a.job.clone(),
            })
            .await
            .map_err(|s| status_err(&a.connect, s))?
            .into_inner();
        let mut bar: Option<ProgressBar> = None;
        let mut last = None;
        while let Some(job) = stream
            .message()
            .await
            .map_err(|s| status_err(&a.connect, s))?
        {
            let counts = job.counts.unwrap_or_default();
            let b = bar.get_or_insert_with(|| {
                let b = ProgressBar::new(job.count);
                b.set_style(
                    ProgressStyle::with_template("{spinner} {bar:40} {pos}/{len} samples  {msg}")
                        .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                b.enable_steady_tick(Duration::from_millis(200));
                b
            });
            b.set_position(counts.done + counts.failed);
            b.set_message(format!(
                "{:.2} samples/s  eta {}  leased {}  failed {}  [{}]",
                job.samples_per_second,
                if job.eta_seconds > 0.0 {
                    format!("{:.0}s", job.eta_seconds)
                } else {
                    "-".into()
                },
                counts.leased,
                counts.failed,
                state_name(job.state)
            ));
            last = Some(job);
        }
        if let Some(b) = bar {
            b.finish();
        }
        let Some(job) = last else {
            bail!("the coordinator sent nothing for {}", a.job)
        };
        let counts = job.counts.unwrap_or_default();
        println!(
            "{}: {} — {} done, {} failed of {}",
            job.id,
            state_name(job.state),
            counts.done,
            counts.failed,
            job.count
        );
        for f in &job.failures {
            println!("  sample {} on {}: {}", f.index, f.worker_id, f.reason);
        }
        if job.state == pb::JobState::Failed as i32 {
            bail!("{} failed samples", counts.failed);
        }
        Ok(())
    })
}

pub fn jobs(a: JobsArgs) -> Result<()> {
    runtime()?.block_on(async {
        let mut c = jobs_client(&a.connect)?;
        let jobs = c
            .list_jobs(pb::ListJobsRequest {})
            .await
            .map_err(|s| status_err(&a.connect, s))?
            .into_inner()
            .jobs;
        println!(
            "{:<28} {:<10} {:>8} {:>8} {:>8} {:>8} {:>8}",
            "JOB", "STATE", "SAMPLES", "DONE", "LEASED", "FAILED", "PRIO"
        );
        for j in jobs {
            let c = j.counts.unwrap_or_default();
            println!(
                "{:<28} {:<10} {:>8} {:>8} {:>8} {:>8} {:>8}",
                j.id,
                state_name(j.state),
                j.count,
                c.done,
                c.leased,
                c.failed,
                j.priority
            );
        }
        Ok(())
    })
}

pub fn job_action(a: JobArgs, action: &str) -> Result<()> {
    runtime()?.block_on(async {
        let mut c = jobs_client(&a.connect)?;
        let r = pb::JobRef {
            job_id: a.job.clone(),
        };
        let job = match action {
            "cancel" => c.cancel_job(r).await,
            "pause" => c.pause_job(r).await,
            _ => c.resume_job(r).await,
        }
        .map_err(|s| status_err(&a.connect, s))?
        .into_inner();
        println!("{}: {}", job.id, state_name(job.state));
        Ok(())
    })
}

pub fn samples(a: SamplesArgs) -> Result<()> {
    runtime()?.block_on(async {
        let mut c = samples_client(&a.connect)?;
        let r = c
            .list_samples(pb::ListSamplesRequest {
                job_id: a.job.clone().unwrap_or_default(),
                split: a.split.clone().unwrap_or_default(),
                offset: 0,
                limit: a.limit,
            })
            .await
            .map_err(|s| status_err(&a.connect, s))?
            .into_inner();
        println!(
            "{:<28} {:>8} {:<6} {:>10} BLAKE3",
            "JOB", "INDEX", "SPLIT", "BYTES"
        );
        for s in &r.samples {
            println!(
                "{:<28} {:>8} {:<6} {:>10} {}",
                s.job_id, s.index, s.split, s.size, s.blake3
            );
        }
        eprintln!("{} of {} samples", r.samples.len(), r.total);
        Ok(())
    })
}

/// Streams a job's committed samples and writes them in the chosen export format.
pub fn export(a: ExportArgs) -> Result<()> {
    runtime()?.block_on(async {
        let mut c = samples_client(&a.connect)?;
        let mut stream = c
            .stream_samples(pb::StreamSamplesRequest {
                job_id: a.job.clone(),
                split: String::new(),
                cursor: 0,
                follow: false,
                metadata_only: false,
            })
            .await
            .map_err(|s| status_err(&a.connect, s))?
            .into_inner();
        let format = match a.format {
            Format::Webdataset => lightfarm_store::ExportFormat::WebDataset {
                samples_per_shard: a.shard_size.max(1),
            },
            Format::Folder => lightfarm_store::ExportFormat::Folder,
        };
        let mut writer = lightfarm_store::ExportWriter::create(&a.out, &a.job, &format)?;
        let bar = ProgressBar::new_spinner();
        let mut samples = SampleAssembler::default();
        let mut add = |sample: Option<(lightfarm_store::SampleRecord, Vec<u8>)>| -> Result<()> {
            if let Some((record, bytes)) = sample {
                writer.add(&record, &bytes)?;
                bar.inc(1);
            }
            Ok(())
        };
        while let Some(chunk) = stream
            .message()
            .await
            .map_err(|s| status_err(&a.connect, s))?
        {
            add(samples.push(chunk).map_err(anyhow::Error::msg)?)?;
        }
        add(samples.finish())?;
        let report = writer.finish()?;
        bar.finish_and_clear();
        eprintln!(
            "{}: {} samples, {} files, {} bytes",
            a.out.display(),
            report.samples,
            report.files.len(),
            report.bytes
        );
        Ok(())
    })
}
