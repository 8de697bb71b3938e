//! An in-process farm for cross-service tests: a coordinator serving real gRPC on a local port
//! that a test can stop (its runtime dropped with every connection and task, as a crash would
//! leave them) and start again on the same port and data, render workers, and the clients the
//! tests need.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use lightfarm_coordinator::service::SampleAssembler;
use lightfarm_coordinator::{Coordinator, CoordinatorConfig};
use lightfarm_proto::client::{channel, AuthedChannel};
use lightfarm_proto::v1 as pb;
use lightfarm_scene::Catalog;

pub const TOKEN: &str = "integration-token";

pub struct Farm {
    pub dir: tempfile::TempDir,
    pub port: u16,
    coordinator: Option<tokio::runtime::Runtime>,
    /// Clients and workers run here, so they outlive a coordinator restart.
    rt: tokio::runtime::Runtime,
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

impl Farm {
    /// A farm with its coordinator running.
    pub fn start() -> Farm {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .expect("client runtime");
        let mut farm = Farm {
            dir: tempfile::tempdir().expect("tempdir"),
            port: free_port(),
            coordinator: None,
            rt,
        };
        farm.start_coordinator();
        farm
    }

    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// `farm://` address of `job` on this farm.
    pub fn address(&self, job: &str) -> String {
        format!("farm://127.0.0.1:{}/{job}", self.port)
    }

    /// Opens the coordinator's data directory (waiting for a stopped one's lock to go) and
    /// serves it on the farm's port.
    pub fn start_coordinator(&mut self) {
        assert!(self.coordinator.is_none(), "the coordinator is running");
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .expect("coordinator runtime");
        let data = self.dir.path().join("coordinator");
        let started = Instant::now();
        let coordinator = loop {
            let config = CoordinatorConfig::new(
                data.clone(),
                TOKEN.into(),
                Catalog::builtin().expect("catalog"),
            );
            match Coordinator::open(config) {
                Ok(c) => break c,
                Err(e) if started.elapsed() < Duration::from_secs(20) => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(100));
                }
                Err(e) => panic!("reopening the coordinator: {e}"),
            }
        };
        let port = self.port;
        let listener = rt.block_on(async {
            let started = Instant::now();
            loop {
                match tokio::net::TcpListener::bind(("127.0.0.1", port)).await {
                    Ok(l) => break l,
                    Err(_) if started.elapsed() < Duration::from_secs(20) => {
                        tokio::time::sleep(Duration::from_millis(100)).await
                    }
                    Err(e) => panic!("binding port {port} again: {e}"),
                }
            }
        });
        rt.spawn(coordinator.serve(listener, std::future::pending()));
        self.coordinator = Some(rt);
    }

    /// Drops the coordinator with its connections and tasks, without a graceful shutdown.
    pub fn stop_coordinator(&mut self) {
        if let Some(rt) = self.coordinator.take() {
            rt.shutdown_timeout(Duration::from_secs(5));
        }
    }

    fn channel(&self, token: &str) -> (tonic::transport::Channel, lightfarm_proto::client::Auth) {
        let _entered = self.rt.enter();
        channel(&self.url(), token, None).expect("channel")
    }

    fn jobs(&self) -> pb::jobs_client::JobsClient<AuthedChannel> {
        let (ch, auth) = self.channel(TOKEN);
        pb::jobs_client::JobsClient::with_interceptor(ch, auth)
    }

    pub fn submit(&self, spec_toml: &str) -> pb::Job {
        let mut jobs = self.jobs();
        self.rt
            .block_on(jobs.submit_dataset(pb::SubmitDatasetRequest {
                spec: Some(pb::submit_dataset_request::Spec::Toml(spec_toml.into())),
                priority: 0,
            }))
            .expect("submit")
            .into_inner()
    }

    pub fn job(&self, id: &str) -> pb::Job {
        let mut jobs = self.jobs();
        self.rt
            .block_on(jobs.get_job(pb::JobRef { job_id: id.into() }))
            .expect("get job")
            .into_inner()
    }

    /// Waits until `id` has committed every sample.
    pub fn wait_done(&self, id: &str, timeout: Duration) {
        let started = Instant::now();
        loop {
            let job = self.job(id);
            let c = job.counts.unwrap_or_default();
            if c.done == job.count {
                return;
            }
            assert!(
                started.elapsed() < timeout,
                "job {id}: {} of {} samples after {timeout:?}",
                c.done,
                job.count
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// A render worker that exits after `samples` samples; it waits out coordinator outages.
    pub fn spawn_worker(&self, name: &str, samples: u64) -> tokio::task::JoinHandle<()> {
        let config = lightfarm_worker::WorkerConfig {
            coordinator: self.url(),
            token: TOKEN.into(),
            name: name.into(),
            cache_dir: self.dir.path().join(format!("worker-{name}")),
            device: "auto".into(),
            tls_ca: None,
            max_samples: Some(samples),
        };
        self.rt.spawn(async move {
            lightfarm_worker::run(config, std::future::pending())
                .await
                .expect("the worker runs");
        })
    }

    /// Runs a worker until it has rendered `samples` samples.
    pub fn run_worker(&self, name: &str, samples: u64) {
        let handle = self.spawn_worker(name, samples);
        self.rt.block_on(handle).expect("worker task");
    }

    pub fn join(&self, handle: tokio::task::JoinHandle<()>) {
        self.rt.block_on(handle).expect("worker task");
    }

    /// `lightfarm export JOB --format folder --out OUT`, through the same API.
    pub fn export_folder(&self, job: &str, out: &Path) -> PathBuf {
        self.export(job, out, &lightfarm_store::ExportFormat::Folder)
    }

    /// `lightfarm export JOB --format FORMAT --out OUT`, through the same API.
    pub fn export(&self, job: &str, out: &Path, format: &lightfarm_store::ExportFormat) -> PathBuf {
        let (ch, auth) = self.channel(TOKEN);
        let mut samples = pb::samples_client::SamplesClient::with_interceptor(ch, auth)
            .max_decoding_message_size(64 << 20);
        self.rt.block_on(async {
            let mut stream = samples
                .stream_samples(pb::StreamSamplesRequest {
                    job_id: job.into(),
                    split: String::new(),
                    cursor: 0,
                    follow: false,
                    metadata_only: false,
                })
                .await
                .expect("stream")
                .into_inner();
            let mut writer =
                lightfarm_store::ExportWriter::create(out, job, format).expect("export dir");
            let mut assembler = SampleAssembler::default();
            while let Some(chunk) = stream.message().await.expect("chunk") {
                if let Some((record, bytes)) = assembler.push(chunk).expect("protocol") {
                    writer.add(&record, &bytes).expect("export add");
                }
            }
            if let Some((record, bytes)) = assembler.finish() {
                writer.add(&record, &bytes).expect("export add");
            }
            writer.finish().expect("export finish");
        });
        out.to_owned()
    }
}

impl Drop for Farm {
    fn drop(&mut self) {
        self.stop_coordinator();
    }
}
