//! The trainer as a gRPC service (`proto/lightfarm/v1/trainer.proto`): train jobs queued and run
//! one at a time on a background thread, each in `data/jobs/<id>/` (job.json + its run
//! directory). A restart — including after `kill -9` — re-queues unfinished jobs, which resume
//! from their newest checkpoint.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};

use lightfarm_proto::v1 as pb;
use lightfarm_scene::Catalog;
use serde::{Deserialize, Serialize};
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

use crate::config::TrainConfig;
use crate::farm::FarmAddress;
use crate::image_io::{gray_png_bytes, load_portrait, png_bytes};
use crate::infer::{load_model, normal_colours};
use crate::lights::{identity_camera, Lighting};
use crate::train::{latest_checkpoint, read_losses, write_atomic, CHECKPOINTS, LATEST};
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
}

struct Job {
    record: JobRecord,
    step: u64,
    cancel: Arc<AtomicBool>,
    updates: tokio::sync::broadcast::Sender<Option<StepLog>>,
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
            let step = read_losses(&path.with_file_name(RUN_DIR))
                .map(|l| l.last().map_or(0, |l| l.step))
                .unwrap_or(0);
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
            updates: tokio::sync::broadcast::Sender<Option<StepLog>>,
        }
        impl Observer for Publish<'_> {
            fn on_step(&mut self, log: &StepLog) {
                if let Some(job) = self
                    .svc
                    .0
                    .jobs
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .get_mut(self.id)
                {
                    job.step = log.step;
                }
                let _ = self.updates.send(Some(log.clone()));
            }
        }
        let result = self.config_of(&record).and_then(|cfg| {
            crate::train(
                &cfg,
                self.0.cfg.catalog.clone(),
                &mut Publish {
                    svc: self,
                    id,
                    updates,
                },
                &cancel,
            )
        });
        match result {
            Ok(s) if s.cancelled => self.set_state(id, pb::TrainJobState::Cancelled, String::new()),
            Ok(_) => self.set_state(id, pb::TrainJobState::Completed, String::new()),
            Err(e) => {
                tracing::error!(job = id, "training failed: {e}");
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
        cfg.vgg_weights = cfg.vgg_weights.map(|v| {
            if crate::config::is_keyword(&v) {
                v
            } else {
                self.0.cfg.datasets.join(v)
            }
        });
        cfg.validate().map_err(TrainError::Config)?;
        Ok(cfg)
    }

    fn to_pb(job: &Job) -> pb::TrainJob {
        pb::TrainJob {
            id: job.record.id.clone(),
            state: job.record.state,
            step: job.step,
            steps: job.record.steps,
            dataset: job.record.dataset.clone(),
            error: job.record.error.clone(),
            config_toml: job.record.config_toml.clone(),
        }
    }

    fn get(&self, id: &str) -> Result<pb::TrainJob, Status> {
        let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
        jobs.get(id)
            .map(Self::to_pb)
            .ok_or_else(|| Status::not_found(format!("no train job '{id}'")))
    }
}

fn loss_point(l: &StepLog) -> pb::LossPoint {
    pb::LossPoint {
        step: l.step,
        total: l.total,
        normal: l.normal,
        normal_lens: l.normal_lens,
        albedo: l.albedo,
        relit: l.relit,
        residual: l.residual.unwrap_or(0.0),
        adversarial: l.adversarial.unwrap_or(0.0),
        critic: l.critic.unwrap_or(0.0),
        samples_per_second: l.samples_per_second,
        perceptual: l.perceptual.unwrap_or(0.0),
    }
}

/// A dataset (or weights) path must stay inside the datasets root.
fn relative_dataset(path: &str) -> Result<PathBuf, Status> {
    under_datasets("dataset", "a folder export's", path)
}

fn under_datasets(key: &str, what: &str, path: &str) -> Result<PathBuf, Status> {
    let p = Path::new(path);
    if path.is_empty()
        || p.is_absolute()
        || p.components()
            .any(|c| !matches!(c, std::path::Component::Normal(_)))
    {
        return Err(Status::invalid_argument(format!(
            "{key} '{path}': give {what} path relative to the trainer's --datasets directory"
        )));
    }
    Ok(p.to_owned())
}

#[tonic::async_trait]
impl pb::trainer_server::Trainer for TrainerService {
    async fn submit_train_job(
        &self,
        req: Request<pb::SubmitTrainJobRequest>,
    ) -> Result<Response<pb::TrainJob>, Status> {
        let r = req.into_inner();
        // `out` is the service's to set, and `dataset` is a name under its --datasets root:
        // taken from the request, else from the config a user also trains with locally.
        let mut table: toml::Table = toml::from_str(&r.config_toml)
            .map_err(|e| Status::invalid_argument(format!("config_toml: {e}")))?;
        let from_config = table
            .remove("dataset")
            .and_then(|v| v.as_str().map(str::to_owned));
        table.remove("out");
        let named = if r.dataset.is_empty() {
            from_config.unwrap_or_default()
        } else {
            r.dataset.clone()
        };
        let farm = FarmAddress::is_farm(&named);
        let dataset = if farm {
            FarmAddress::parse(&named).map_err(|e| Status::invalid_argument(e.to_string()))?;
            PathBuf::from(&named)
        } else {
            relative_dataset(&named)?
        };
        table.insert("dataset".into(), "-".into());
        table.insert("out".into(), "-".into());
        let mut cfg: TrainConfig = table
            .try_into()
            .map_err(|e: toml::de::Error| Status::invalid_argument(format!("config_toml: {e}")))?;
        if !r.split.is_empty() {
            cfg.split = r.split;
        }
        if r.steps > 0 {
            cfg.steps = r.steps;
        }
        if r.batch > 0 {
            cfg.batch = r.batch as usize;
        }
        cfg.validate()
            .map_err(|e| Status::invalid_argument(format!("config: {e}")))?;
        if let Some(v) = cfg
            .vgg_weights
            .as_ref()
            .filter(|v| !crate::config::is_keyword(v))
        {
            let rel = under_datasets("vgg_weights", "a safetensors file's", &v.to_string_lossy())?;
            if !self.0.cfg.datasets.join(&rel).is_file() {
                return Err(Status::failed_precondition(format!(
                    "vgg_weights '{}': no such file under the trainer's --datasets directory",
                    v.display()
                )));
            }
        }
        if cfg.stream.tls_ca.is_some() || cfg.stream.cache_dir.is_some() {
            return Err(Status::invalid_argument(
                "[stream] tls_ca and cache_dir are the trainer service's to set; remove them",
            ));
        }
        if farm {
            // Checked when the job starts (the coordinator may be busy or restarting now).
            if self.0.cfg.coordinator_token.is_none() {
                return Err(Status::failed_precondition(
                    "this trainer has no coordinator token for farm:// datasets: start it with \
                     --coordinator-token (or LIGHTFARM_COORDINATOR_TOKEN)",
                ));
            }
        } else {
            let full = self.0.cfg.datasets.join(&dataset);
            crate::data::Dataset::open(&full, &cfg.split)
                .map_err(|e| Status::failed_precondition(e.to_string()))?;
        }
        let id = {
            let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
            format!("train-{:06}", jobs.len() + 1)
        };
        let record = JobRecord {
            id: id.clone(),
            state: pb::TrainJobState::Queued as i32,
            steps: cfg.steps,
            dataset: dataset.to_string_lossy().into_owned(),
            error: String::new(),
            config_toml: toml::to_string(&cfg).map_err(internal)?,
        };
        self.persist(&record).map_err(internal)?;
        let job = Job {
            record,
            step: 0,
            cancel: Arc::default(),
            updates: tokio::sync::broadcast::channel(1024).0,
        };
        let pb_job = Self::to_pb(&job);
        self.0
            .jobs
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(id.clone(), job);
        self.0
            .queue
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .send(id)
            .map_err(internal)?;
        Ok(Response::new(pb_job))
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
        let first = pb::TrainProgress {
            job: Some(self.get(&id)?),
            losses: read_losses(&self.job_dir(&id).join(RUN_DIR))
                .unwrap_or_default()
                .iter()
                .map(loss_point)
                .collect(),
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
                    losses: point.iter().map(loss_point).collect(),
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
            jobs: jobs.values().map(Self::to_pb).collect(),
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
                "train job '{}' has no checkpoint yet",
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
    fn relight_blocking(
        &self,
        run: &Path,
        r: pb::RelightRequest,
    ) -> Result<pb::RelightResponse, Status> {
        let bad = |e: TrainError| Status::invalid_argument(e.to_string());
        let tmp = tempfile::tempdir().map_err(internal)?;
        let image = tmp.path().join("image");
        std::fs::write(&image, &r.image).map_err(internal)?;
        let mask = if r.mask.is_empty() {
            None
        } else {
            let m = tmp.path().join("mask");
            std::fs::write(&m, &r.mask).map_err(internal)?;
            Some(m)
        };
        let lighting = match r.lighting {
            Some(pb::relight_request::Lighting::HdriId(id)) => {
                let asset = self
                    .0
                    .cfg
                    .catalog
                    .get(&id)
                    .filter(|a| a.kind == lightfarm_scene::AssetKind::Hdri)
                    .ok_or_else(|| {
                        Status::invalid_argument(format!(
                            "hdri_id '{id}' is not an HDRI of the trainer's catalog"
                        ))
                    })?;
                Lighting::load(&self.0.cfg.catalog.path_of(asset)).map_err(bad)?
            }
            Some(pb::relight_request::Lighting::HdriFile(bytes)) => {
                let ext = if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
                    "exr"
                } else {
                    "hdr"
                };
                let p = tmp.path().join(format!("env.{ext}"));
                std::fs::write(&p, &bytes).map_err(internal)?;
                Lighting::load(&p).map_err(bad)?
            }
            None => return Err(Status::invalid_argument("give hdri_id or hdri_file")),
        };
        let model = load_model(run, &self.0.cfg.device).map_err(internal)?;
        let matte = (!r.no_matte).then_some(&self.0.matting);
        let p = load_portrait(&image, mask.as_deref(), matte).map_err(|e| match e {
            // The trainer's installation lacks MODNet: not the caller's input.
            TrainError::Photo(lightfarm_photo::PhotoError::Model { .. }) => {
                Status::failed_precondition(e.to_string())
            }
            e => bad(e),
        })?;
        let rot = identity_camera(r.rotation_deg, r.flip);
        let (w, h) = (p.width, p.height);
        let out = model
            .relight(&p.rgb, &p.mask, w, h, &lighting, rot)
            .map_err(internal)?;
        let relit = out.with_inset(&lighting, rot);
        let png = |rgb: &[[f32; 3]]| png_bytes(w, h, rgb).map_err(internal);
        Ok(pb::RelightResponse {
            width: w as u32,
            height: h as u32,
            relit_png: png(&relit)?,
            normal_png: png(&normal_colours(&out.normal))?,
            albedo_png: png(&out.albedo)?,
            diffuse_png: png(&out.diffuse)?,
            specular_png: png(&out.specular)?,
            mask_png: gray_png_bytes(w, h, &p.mask).map_err(internal)?,
            matted: p.matted,
        })
    }

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
