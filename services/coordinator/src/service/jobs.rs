//! `Jobs`: submit, list, watch, pause, resume and cancel dataset jobs.

use super::*;

pub struct JobsService(pub Arc<Shared>);

#[tonic::async_trait]
impl pb::jobs_server::Jobs for JobsService {
    async fn submit_dataset(
        &self,
        req: Request<pb::SubmitDatasetRequest>,
    ) -> Result<Response<pb::Job>, Status> {
        let req = req.into_inner();
        let toml_text = match req.spec {
            Some(pb::submit_dataset_request::Spec::Toml(t)) => t,
            Some(pb::submit_dataset_request::Spec::Json(j)) => {
                let value: toml::Value = serde_json::from_str(&j).map_err(|e| {
                    Status::invalid_argument(format!("spec JSON does not parse: {e}"))
                })?;
                toml::to_string(&value).map_err(|e| {
                    Status::invalid_argument(format!("spec JSON is not a TOML document: {e}"))
                })?
            }
            None => {
                return Err(Status::invalid_argument(
                    "give the dataset spec (toml or json)",
                ))
            }
        };
        let s = self.0.scheduler.clone();
        let status =
            tokio::task::spawn_blocking(move || s.submit(&toml_text, req.priority, now_unix()))
                .await
                .map_err(|e| Status::internal(e.to_string()))??;
        Ok(Response::new(job_to_pb(&status)))
    }

    async fn get_server_info(
        &self,
        _req: Request<pb::ServerInfoRequest>,
    ) -> Result<Response<pb::ServerInfo>, Status> {
        Ok(Response::new(pb::ServerInfo {
            protocol_version: lightfarm_proto::PROTOCOL_VERSION,
            server_version: env!("CARGO_PKG_VERSION").to_owned(),
        }))
    }

    async fn get_job(&self, req: Request<pb::JobRef>) -> Result<Response<pb::Job>, Status> {
        let s = self.0.scheduler.job(&req.into_inner().job_id, now_unix())?;
        Ok(Response::new(job_to_pb(&s)))
    }

    async fn list_jobs(
        &self,
        _req: Request<pb::ListJobsRequest>,
    ) -> Result<Response<pb::ListJobsResponse>, Status> {
        let jobs = self
            .0
            .scheduler
            .jobs(now_unix())
            .iter()
            .map(job_to_pb)
            .collect();
        Ok(Response::new(pb::ListJobsResponse { jobs }))
    }

    type WatchJobStream = BoxStream<pb::Job>;

    async fn watch_job(
        &self,
        req: Request<pb::JobRef>,
    ) -> Result<Response<Self::WatchJobStream>, Status> {
        let job_id = req.into_inner().job_id;
        let sched = self.0.scheduler.clone();
        // Fail fast on an unknown job.
        sched.job(&job_id, now_unix())?;
        let mut changes = sched.subscribe();
        let (tx, rx) = mpsc::channel(4);
        tokio::spawn(async move {
            let mut last: Option<pb::Job> = None;
            loop {
                let status = match sched.job(&job_id, now_unix()) {
                    Ok(s) => s,
                    Err(e) => {
                        let _ = tx.send(Err(e.into())).await;
                        return;
                    }
                };
                let job = job_to_pb(&status);
                if last.as_ref() != Some(&job) {
                    if tx.send(Ok(job.clone())).await.is_err() {
                        return;
                    }
                    last = Some(job);
                }
                if status.finished() {
                    return;
                }
                // At most 10 updates a second, and one every 5 s for the rate/ETA.
                tokio::time::sleep(Duration::from_millis(100)).await;
                let _ = tokio::time::timeout(Duration::from_secs(5), changes.changed()).await;
            }
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }

    async fn cancel_job(&self, req: Request<pb::JobRef>) -> Result<Response<pb::Job>, Status> {
        let s = self.0.scheduler.set_run_state(
            &req.into_inner().job_id,
            RunState::Cancelled,
            now_unix(),
        )?;
        Ok(Response::new(job_to_pb(&s)))
    }

    async fn pause_job(&self, req: Request<pb::JobRef>) -> Result<Response<pb::Job>, Status> {
        let s = self.0.scheduler.set_run_state(
            &req.into_inner().job_id,
            RunState::Paused,
            now_unix(),
        )?;
        Ok(Response::new(job_to_pb(&s)))
    }

    async fn resume_job(&self, req: Request<pb::JobRef>) -> Result<Response<pb::Job>, Status> {
        let s = self.0.scheduler.set_run_state(
            &req.into_inner().job_id,
            RunState::Running,
            now_unix(),
        )?;
        Ok(Response::new(job_to_pb(&s)))
    }
}
