//! `SubmitTrainJob` and `SubmitAdaptJob`: a request checked against the trainer's datasets
//! root and jobs, turned into a job record (the effective config as TOML) and queued.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use lightfarm_proto::v1 as pb;
use tonic::Status;

use super::{internal, JobRecord, TrainerService, RUN_DIR};
use crate::adapt::AdaptConfig;
use crate::config::TrainConfig;
use crate::farm::FarmAddress;
use crate::train::latest_checkpoint;

impl TrainerService {
    pub(super) fn submit_train(
        &self,
        r: pb::SubmitTrainJobRequest,
    ) -> Result<pb::TrainJob, Status> {
        // `out` is the service's to set, and `dataset` is a name under its --datasets root:
        // taken from the request, else from the config a user also trains with locally.
        let (table, named) = split_request(&r.config_toml, "dataset", &r.dataset, &["out"])?;
        let farm = FarmAddress::is_farm(&named);
        let dataset = if farm {
            FarmAddress::parse(&named).map_err(|e| Status::invalid_argument(e.to_string()))?;
            PathBuf::from(&named)
        } else {
            relative_dataset(&named)?
        };
        let mut cfg: TrainConfig = with_placeholders(table, &["dataset", "out"])?;
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
        self.check_vgg_weights(cfg.vgg_weights.as_deref())?;
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
        self.enqueue(JobRecord {
            id: String::new(),
            state: pb::TrainJobState::Queued as i32,
            steps: cfg.steps,
            dataset: dataset.to_string_lossy().into_owned(),
            error: String::new(),
            config_toml: toml::to_string(&cfg).map_err(internal)?,
            kind: pb::TrainJobKind::Train as i32,
            base_job_id: String::new(),
            base_checkpoint: String::new(),
        })
    }

    pub(super) fn submit_adapt(
        &self,
        r: pb::SubmitAdaptJobRequest,
    ) -> Result<pb::TrainJob, Status> {
        // `base`, `photos` and `out` are the service's to set: the base is a job of this
        // trainer, the photos a folder under its --datasets root.
        let (table, named) = split_request(&r.config_toml, "photos", &r.photos, &["base", "out"])?;
        let photos = under_datasets("photos", "a photo folder's", &named)?;
        let mut cfg: AdaptConfig = with_placeholders(table, &["base", "photos", "out"])?;
        if r.steps > 0 {
            cfg.steps = r.steps;
        }
        cfg.validate()
            .map_err(|e| Status::invalid_argument(format!("config: {e}")))?;
        if cfg.assets.is_some() {
            return Err(Status::invalid_argument(
                "assets is the trainer service's to set (its catalog); remove it",
            ));
        }
        self.check_vgg_weights(cfg.vgg_weights.as_deref())?;
        if !self.0.cfg.datasets.join(&photos).is_dir() {
            return Err(Status::failed_precondition(format!(
                "photos '{named}': no such folder under the trainer's --datasets directory"
            )));
        }
        let base_checkpoint = self.base_checkpoint(&r.base_job_id)?;
        self.enqueue(JobRecord {
            id: String::new(),
            state: pb::TrainJobState::Queued as i32,
            steps: cfg.steps,
            dataset: photos.to_string_lossy().into_owned(),
            error: String::new(),
            config_toml: toml::to_string(&cfg).map_err(internal)?,
            kind: pb::TrainJobKind::Adapt as i32,
            base_job_id: r.base_job_id,
            base_checkpoint,
        })
    }

    /// The newest checkpoint of train job `id`, relative to the service's data directory; the
    /// job must have ended, so that checkpoint stays (a running job prunes old ones).
    fn base_checkpoint(&self, id: &str) -> Result<String, Status> {
        if id.is_empty() {
            return Err(Status::invalid_argument(
                "base_job_id: name the train job whose model to adapt (ListTrainJobs)",
            ));
        }
        let record = {
            let jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
            jobs.get(id)
                .map(|j| j.record.clone())
                .ok_or_else(|| Status::not_found(format!("base_job_id: no train job '{id}'")))?
        };
        if record.kind() != pb::TrainJobKind::Train {
            return Err(Status::invalid_argument(format!(
                "base_job_id '{id}' is an adaptation job; adapt the train job it adapted ('{}')",
                record.base_job_id
            )));
        }
        let ended = [pb::TrainJobState::Completed, pb::TrainJobState::Cancelled]
            .iter()
            .any(|s| *s as i32 == record.state);
        if !ended {
            return Err(Status::failed_precondition(format!(
                "base_job_id '{id}' has not ended ({:?}); adapt its final model once it completes",
                pb::TrainJobState::try_from(record.state).unwrap_or(pb::TrainJobState::Unspecified)
            )));
        }
        let run = self.job_dir(id).join(RUN_DIR);
        let dir = latest_checkpoint(&run).map_err(internal)?.ok_or_else(|| {
            Status::failed_precondition(format!("base_job_id '{id}' has no checkpoint"))
        })?;
        let rel = dir
            .strip_prefix(&self.0.cfg.data)
            .map_err(internal)?
            .to_string_lossy()
            .into_owned();
        Ok(rel)
    }

    /// `vgg_weights` other than a keyword must be a file under the datasets root.
    fn check_vgg_weights(&self, v: Option<&Path>) -> Result<(), Status> {
        if let Some(v) = v.filter(|v| !crate::config::is_keyword(v)) {
            let rel = under_datasets("vgg_weights", "a safetensors file's", &v.to_string_lossy())?;
            if !self.0.cfg.datasets.join(&rel).is_file() {
                return Err(Status::failed_precondition(format!(
                    "vgg_weights '{}': no such file under the trainer's --datasets directory",
                    v.display()
                )));
            }
        }
        Ok(())
    }

    /// Gives the record its id, saves it and queues it.
    fn enqueue(&self, mut record: JobRecord) -> Result<pb::TrainJob, Status> {
        let prefix = match record.kind() {
            pb::TrainJobKind::Adapt => "adapt",
            _ => "train",
        };
        let mut jobs = self.0.jobs.lock().unwrap_or_else(|p| p.into_inner());
        record.id = format!("{prefix}-{:06}", jobs.len() + 1);
        let id = record.id.clone();
        self.persist(&record).map_err(internal)?;
        let job = super::Job {
            record,
            step: 0,
            cancel: Arc::default(),
            updates: tokio::sync::broadcast::channel(1024).0,
        };
        let pb_job = self.to_pb(&job);
        jobs.insert(id.clone(), job);
        drop(jobs);
        self.0
            .queue
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .send(id)
            .map_err(internal)?;
        Ok(pb_job)
    }
}

/// A request's config TOML without the keys the service sets (`service_keys`, and `key`), and
/// the folder the job works on: the request's `requested`, else the config's `key`.
fn split_request(
    config_toml: &str,
    key: &str,
    requested: &str,
    service_keys: &[&str],
) -> Result<(toml::Table, String), Status> {
    let mut table: toml::Table = toml::from_str(config_toml)
        .map_err(|e| Status::invalid_argument(format!("config_toml: {e}")))?;
    let from_config = table
        .remove(key)
        .and_then(|v| v.as_str().map(str::to_owned));
    for k in service_keys {
        table.remove(*k);
    }
    let named = if requested.is_empty() {
        from_config.unwrap_or_default()
    } else {
        requested.to_owned()
    };
    Ok((table, named))
}

/// The config, with placeholders for the required keys the service fills in when the job runs.
fn with_placeholders<T: serde::de::DeserializeOwned>(
    mut table: toml::Table,
    keys: &[&str],
) -> Result<T, Status> {
    for k in keys {
        table.insert((*k).into(), "-".into());
    }
    table
        .try_into()
        .map_err(|e: toml::de::Error| Status::invalid_argument(format!("config_toml: {e}")))
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
