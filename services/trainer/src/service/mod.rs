//! The trainer as a gRPC service (`proto/lightfarm/v1/trainer.proto`): train jobs and
//! adaptation jobs (a completed train job's model adapted to a folder of real photos) queued
//! and run one at a time on a background thread, each in `data/jobs/<id>/` (job.json + its run
//! directory). A restart — including after `kill -9` — re-queues unfinished jobs, which resume
//! from their newest checkpoint.
//!
//! `submit` checks requests and queues jobs, `progress` turns both kinds of loss log into
//! `LossPoint`s, `relight` serves `Relight`.

mod progress;
mod relight;
mod submit;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};

use lightfarm_proto::v1 as pb;
use lightfarm_scene::Catalog;
use serde::{Deserialize, Serialize};
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

use crate::adapt::{AdaptConfig, AdaptLog, AdaptObserver};
use crate::config::TrainConfig;
use crate::farm::FarmAddress;
use crate::train::{latest_checkpoint, write_atomic, CHECKPOINTS, LATEST};
use crate::{Observer, StepLog, TrainError};

const JOB_FILE: &str = "job.json";
const RUN_DIR: &str = "run";

pub struct ServiceConfig {
    /// Job records and run directories.
    pub data: PathBuf,
    /// Root that `SubmitTrainJobRequest.dataset` paths are relative to.
    pub datasets: PathBuf,
    pub catalog: Catalog,
    /// Training device for every job: auto, cpu or gpu.
    pub device: String,
    /// Bearer token for the coordinators of `farm://` datasets.
    pub coordinator_token: Option<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct JobRecord {
    id: String,
    state: i32,
    steps: u64,
    dataset: String,
    error: String,
    config_toml: String,
    /// A `pb::TrainJobKind`; records from before adaptation jobs have none (train).
    #[serde(default)]
    kind: i32,
    /// ADAPT: the train job adapted, and its checkpoint directory relative to the data
    /// directory, fixed at submission.
    #[serde(default)]
    base_job_id: String,
    #[serde(default)]
    base_checkpoint: String,
}

impl JobRecord {
    fn kind(&self) -> pb::TrainJobKind {
        match pb::TrainJobKind::try_from(self.kind) {
            Ok(pb::TrainJobKind::Adapt) => pb::TrainJobKind::Adapt,
            _ => pb::TrainJobKind::Train,
        }
    }
}

struct Job {
    record: JobRecord,
    step: u64,
    cancel: Arc<AtomicBool>,
    updates: tokio::sync::broadcast::Sender<Option<pb::LossPoint>>,
}

struct Inner {
    cfg: ServiceConfig,
    /// MODNet for `Relight` of photos that come without a mask, loaded on first use.
    matting: lightfarm_photo::LazyMatting,
    jobs: Mutex<BTreeMap<String, Job>>,
    queue: Mutex<mpsc::Sender<String>>,
}

#[derive(Clone)]
pub struct TrainerService(Arc<Inner>);

fn terminal(state: i32) -> bool {
    state == pb::TrainJobState::Completed as i32
        || state == pb::TrainJobState::Failed as i32
        || state == pb::TrainJobState::Cancelled as i32
}

fn internal(e: impl std::fmt::Display) -> Status {
    Status::internal(e.to_string())
}

impl TrainerService {
    /// Opens `cfg.data`, re-queues the jobs a previous process left unfinished and starts the
    /// thread that runs them.
    pub fn open(cfg: ServiceConfig) -> Result<TrainerService, TrainError> {
        let jobs_dir = cfg.data.join("jobs");
        std::fs::create_dir_all(&jobs_dir).map_err(|e| TrainError::io(&jobs_dir, e))?;
        let (tx, rx) = mpsc::channel::<String>();
        let mut jobs = BTreeMap::new();
        let mut pending = Vec::new();
        for entry in std::fs::read_dir(&jobs_dir).map_err(|e| TrainError::io(&jobs_dir, e))? {
            let path = entry
                .map_err(|e| TrainError::io(&jobs_dir, e))?
                .path()
                .join(JOB_FILE);
            let Ok(text) = std::fs::read_to_string(&path) else {
                continue;
            };
            let mut record: JobRecord = serde_json::from_str(&text).map_err(|e| {
                TrainError::Input(format!("{}: {e}; move it away to start", path.display()))
            })?;
            if !terminal(record.state) {
                record.state = pb::TrainJobState::Queued as i32;
                pending.push(record.id.clone());
            }
            let step = progress::read_curve(&path.with_file_name(RUN_DIR), record.kind())
                .last()
                .map_or(0, |l| l.step);
            jobs.insert(
                record.id.clone(),
                Job {
                    record,
                    step,
                    cancel: Arc::default(),
                    updates: tokio::sync::broadcast::channel(1024).0,
                },
            );
        }
        pending.sort();
        for id in pending {
            let _ = tx.send(id);
        }
        let svc = TrainerService(Arc::new(Inner {
            cfg,
            matting: lightfarm_photo::LazyMatting::builtin(),
            jobs: Mutex::new(jobs),
            queue: Mutex::new(tx),
        }));
        let runner = svc.clone();
        std::thread::Builder::new()
            .name("train-jobs".into())
            .spawn(move || {
                while let Ok(id) = rx.recv() {
                    runner.run_job(&id);
                }
            })
            .map_err(|e| TrainError::Input(format!("starting the training thread: {e}")))?;
        Ok(svc)
    }

    fn job_dir(&self, id: &str) -> PathBuf {
        self.0.cfg.data.join("jobs").join(id)
    }

    fn persist(&self, record: &JobRecord) -> Result<(), TrainError> {
        let dir = self.job_dir(&record.id);
        std::fs::create_dir_all(&dir).map_err(|e| TrainError::io(&dir, e))?;
        let text =
            serde_json::to_vec_pretty(record).map_err(|e| TrainError::Input(e.to_string()))?;
        write_atomic(&dir.join(JOB_FILE), &text)
    }

    fn set_state(&self, id: &str, state: pb::TrainJobState, error: String) {
        let mut jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(job) = jobs.get_mut(id) {
            job.record.state = state as i32;
            job.record.error = error;
            if let Err(e) = self.persist(&job.record) {
                tracing::error!(job = id, "saving the job record: {e}");
            }
            let _ = job.updates.send(None);
        }
    }

    fn run_job(&self, id: &str) {
        let (record, cancel, updates) = {
            let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
            let Some(job) = jobs.get(id) else { return };
            (job.record.clone(), job.cancel.clone(), job.updates.clone())
        };
        if cancel.load(Ordering::Relaxed) {
            self.set_state(id, pb::TrainJobState::Cancelled, String::new());
            return;
        }
        self.set_state(id, pb::TrainJobState::Running, String::new());
        struct Publish<'a> {
            svc: &'a TrainerService,
            id: &'a str,
            updates: tokio::sync::broadcast::Sender<Option<pb::LossPoint>>,
        }
        impl Publish<'_> {
            fn publish(&mut self, point: pb::LossPoint) {
                if let Some(job) = self
                    .svc
                    .0
                    .jobs
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .get_mut(self.id)
                {
                    job.step = point.step;
                }
                let _ = self.updates.send(Some(point));
            }
        }
        impl Observer for Publish<'_> {
            fn on_step(&mut self, log: &StepLog) {
                self.publish(progress::train_point(log));
            }
        }
        impl AdaptObserver for Publish<'_> {
            fn on_step(&mut self, log: &AdaptLog) {
                self.publish(progress::adapt_point(log));
            }
        }
        let mut publish = Publish {
            svc: self,
            id,
            updates,
        };
        let catalog = self.0.cfg.catalog.clone();
        let result = match record.kind() {
            pb::TrainJobKind::Adapt => self.adapt_config_of(&record).and_then(|cfg| {
                crate::adapt::adapt(&cfg, catalog, &mut publish, &cancel).map(|s| s.cancelled)
            }),
            _ => self.config_of(&record).and_then(|cfg| {
                crate::train(&cfg, catalog, &mut publish, &cancel).map(|s| s.cancelled)
            }),
        };
        match result {
            Ok(true) => self.set_state(id, pb::TrainJobState::Cancelled, String::new()),
            Ok(false) => self.set_state(id, pb::TrainJobState::Completed, String::new()),
            Err(e) => {
                tracing::error!(job = id, "job failed: {e}");
                self.set_state(id, pb::TrainJobState::Failed, e.to_string());
            }
        }
    }

    fn config_of(&self, record: &JobRecord) -> Result<TrainConfig, TrainError> {
        let mut cfg: TrainConfig = toml::from_str(&record.config_toml)
            .map_err(|e| TrainError::Config(format!("job {}: {e}", record.id)))?;
        if FarmAddress::is_farm(&record.dataset) {
            cfg.dataset = PathBuf::from(&record.dataset);
            cfg.token = self.0.cfg.coordinator_token.clone();
        } else {
            cfg.dataset = self.0.cfg.datasets.join(&record.dataset);
        }
        cfg.out = self.job_dir(&record.id).join(RUN_DIR);
        cfg.device = self.0.cfg.device.clone();
        cfg.vgg_weights = self.vgg_weights(cfg.vgg_weights);
        cfg.validate().map_err(TrainError::Config)?;
        Ok(cfg)
    }

    fn adapt_config_of(&self, record: &JobRecord) -> Result<AdaptConfig, TrainError> {
        let mut cfg: AdaptConfig = toml::from_str(&record.config_toml)
            .map_err(|e| TrainError::Config(format!("job {}: {e}", record.id)))?;
        cfg.base = self.0.cfg.data.join(&record.base_checkpoint);
        cfg.photos = self.0.cfg.datasets.join(&record.dataset);
        cfg.out = self.job_dir(&record.id).join(RUN_DIR);
        cfg.device = self.0.cfg.device.clone();
        cfg.vgg_weights = self.vgg_weights(cfg.vgg_weights);
        cfg.validate().map_err(TrainError::Config)?;
        Ok(cfg)
    }

    /// A job's `vgg_weights`: a keyword, or a file under the datasets root.
    fn vgg_weights(&self, v: Option<PathBuf>) -> Option<PathBuf> {
        v.map(|v| {
            if crate::config::is_keyword(&v) {
                v
            } else {
                self.0.cfg.datasets.join(v)
            }
        })
    }

    fn to_pb(&self, job: &Job) -> pb::TrainJob {
        let r = &job.record;
        pb::TrainJob {
            id: r.id.clone(),
            state: r.state,
            step: job.step,
            steps: r.steps,
            dataset: r.dataset.clone(),
            error: r.error.clone(),
            config_toml: r.config_toml.clone(),
            kind: r.kind() as i32,
            base_job_id: r.base_job_id.clone(),
            base_checkpoint: if r.base_checkpoint.is_empty() {
                String::new()
            } else {
                self.0
                    .cfg
                    .data
                    .join(&r.base_checkpoint)
                    .display()
                    .to_string()
            },
        }
    }

    fn get(&self, id: &str) -> Result<pb::TrainJob, Status> {
        let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
        jobs.get(id)
            .map(|j| self.to_pb(j))
            .ok_or_else(|| Status::not_found(format!("no train job '{id}'")))
    }
}

#[tonic::async_trait]
impl pb::trainer_server::Trainer for TrainerService {
    async fn submit_train_job(
        &self,
        req: Request<pb::SubmitTrainJobRequest>,
    ) -> Result<Response<pb::TrainJob>, Status> {
        self.submit_train(req.into_inner()).map(Response::new)
    }

    async fn submit_adapt_job(
        &self,
        req: Request<pb::SubmitAdaptJobRequest>,
    ) -> Result<Response<pb::TrainJob>, Status> {
        self.submit_adapt(req.into_inner()).map(Response::new)
    }

    type WatchTrainJobStream = ReceiverStream<Result<pb::TrainProgress, Status>>;

    async fn watch_train_job(
        &self,
        req: Request<pb::TrainJobRef>,
    ) -> Result<Response<Self::WatchTrainJobStream>, Status> {
        let id = req.into_inner().job_id;
        let mut updates = {
            let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
            jobs.get(&id)
                .ok_or_else(|| Status::not_found(format!("no train job '{id}'")))?
                .updates
                .subscribe()
        };
        let job = self.get(&id)?;
        let kind = pb::TrainJobKind::try_from(job.kind).unwrap_or(pb::TrainJobKind::Train);
        let first = pb::TrainProgress {
            losses: progress::read_curve(&self.job_dir(&id).join(RUN_DIR), kind),
            job: Some(job),
        };
        let (tx, rx) = tokio::sync::mpsc::channel(64);
        let svc = self.clone();
        tokio::spawn(async move {
            let mut job = first.job.clone();
            if tx.send(Ok(first)).await.is_err() {
                return;
            }
            while !job.as_ref().is_some_and(|j| terminal(j.state)) {
                let point = match updates.recv().await {
                    Ok(p) => p,
                    Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => None,
                    Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
                };
                job = svc.get(&id).ok();
                let msg = pb::TrainProgress {
                    job: job.clone(),
                    losses: point.into_iter().collect(),
                };
                if tx.send(Ok(msg)).await.is_err() {
                    return;
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    async fn cancel_train_job(
        &self,
        req: Request<pb::TrainJobRef>,
    ) -> Result<Response<pb::TrainJob>, Status> {
        let id = req.into_inner().job_id;
        let queued = {
            let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
            let job = jobs
                .get(&id)
                .ok_or_else(|| Status::not_found(format!("no train job '{id}'")))?;
            job.cancel.store(true, Ordering::Relaxed);
            job.record.state == pb::TrainJobState::Queued as i32
        };
        if queued {
            self.set_state(&id, pb::TrainJobState::Cancelled, String::new());
        }
        Ok(Response::new(self.get(&id)?))
    }

    async fn list_train_jobs(
        &self,
        _: Request<pb::ListTrainJobsRequest>,
    ) -> Result<Response<pb::ListTrainJobsResponse>, Status> {
        let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
        Ok(Response::new(pb::ListTrainJobsResponse {
            jobs: jobs.values().map(|j| self.to_pb(j)).collect(),
        }))
    }

    async fn list_checkpoints(
        &self,
        req: Request<pb::TrainJobRef>,
    ) -> Result<Response<pb::ListCheckpointsResponse>, Status> {
        let id = req.into_inner().job_id;
        self.get(&id)?;
        let root = self.job_dir(&id).join(RUN_DIR).join(CHECKPOINTS);
        let latest = std::fs::read_to_string(root.join(LATEST)).unwrap_or_default();
        let mut checkpoints: Vec<pb::Checkpoint> = std::fs::read_dir(&root)
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .filter_map(|e| {
                        let name = e.file_name().to_string_lossy().into_owned();
                        let step = name.strip_prefix("step-")?.parse().ok()?;
                        Some(pb::Checkpoint {
                            step,
                            path: e.path().display().to_string(),
                            latest: name == latest.trim(),
                        })
                    })
                    .collect()
            })
            .unwrap_or_default();
        checkpoints.sort_by_key(|c| c.step);
        Ok(Response::new(pb::ListCheckpointsResponse { checkpoints }))
    }

    async fn relight(
        &self,
        req: Request<pb::RelightRequest>,
    ) -> Result<Response<pb::RelightResponse>, Status> {
        let r = req.into_inner();
        self.get(&r.job_id)?;
        let run = self.job_dir(&r.job_id).join(RUN_DIR);
        if latest_checkpoint(&run).map_err(internal)?.is_none() {
            return Err(Status::failed_precondition(format!(
                "job '{}' has no checkpoint yet",
                r.job_id
            )));
        }
        let svc = self.clone();
        tokio::task::spawn_blocking(move || svc.relight_blocking(&run, r))
            .await
            .map_err(internal)?
            .map(Response::new)
    }
}

impl TrainerService {
    /// Serves gRPC (bearer `token`) on `listener` until `shutdown` resolves.
    pub async fn serve(
        self,
        listener: tokio::net::TcpListener,
        token: &str,
        shutdown: impl std::future::Future<Output = ()> + Send + 'static,
    ) -> Result<(), TrainError> {
        let auth = lightfarm_proto::auth::bearer(token, "trainer");
        let server = pb::trainer_server::TrainerServer::new(self)
            .max_decoding_message_size(256 << 20)
            .max_encoding_message_size(256 << 20);
        tonic::transport::Server::builder()
            .add_service(tonic::service::interceptor::InterceptedService::new(
                server, auth,
            ))
            .serve_with_incoming_shutdown(
                tokio_stream::wrappers::TcpListenerStream::new(listener),
                shutdown,
            )
            .await
            .map_err(|e| TrainError::Input(format!("gRPC server: {e}")))
    }
}
