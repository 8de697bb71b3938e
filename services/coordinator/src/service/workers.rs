//! `Workers`: registration, leases, heartbeats, uploads (verified, committed once, made
//! durable before they are acknowledged), failures and asset downloads.

use super::*;

pub struct WorkersService(pub Arc<Shared>);

#[tonic::async_trait]
impl pb::workers_server::Workers for WorkersService {
    async fn register_worker(
        &self,
        req: Request<pb::RegisterWorkerRequest>,
    ) -> Result<Response<pb::RegisterWorkerResponse>, Status> {
        let req = req.into_inner();
        let id = self.0.scheduler.register_worker(
            WorkerHello {
                name: req.name,
                device: req.device.clone(),
                memory_bytes: req.memory_bytes,
                cached: req.cached_assets,
            },
            now_unix(),
        )?;
        tracing::info!(worker = %id, device = %req.device, "worker registered");
        Ok(Response::new(pb::RegisterWorkerResponse {
            worker_id: id,
            lease_seconds: self.0.scheduler.lease_seconds().round() as u32,
            heartbeat_seconds: self.0.heartbeat_seconds,
            max_upload_bytes: self.0.max_upload_bytes,
            catalog_blake3: self.0.catalog_blake3.clone(),
        }))
    }

    async fn lease_tasks(
        &self,
        req: Request<pb::LeaseTasksRequest>,
    ) -> Result<Response<pb::LeaseTasksResponse>, Status> {
        let req = req.into_inner();
        let capacity = req.capacity.clamp(1, 256);
        let cached = (!req.cached_assets.is_empty()).then_some(req.cached_assets);
        let start = std::time::Instant::now();
        // Microseconds of work under one short lock: a blocking-pool hop would cost more.
        let tasks = self
            .0
            .scheduler
            .lease(&req.worker_id, capacity, cached, now_unix())?;
        self.0
            .metrics
            .lease_latency
            .observe(start.elapsed().as_secs_f64());
        self.0.metrics.leased.inc_by(tasks.len() as u64);
        let tasks = tasks
            .into_iter()
            .map(|t| pb::Task {
                job_id: t.job_id,
                index: t.index,
                lease_id: t.lease_id,
                deadline_unix: t.deadline_unix,
                sample_json: t.sample_json,
                assets: t
                    .assets
                    .into_iter()
                    .map(|(id, blake3)| {
                        let size = self.0.assets.get(&blake3).copied().unwrap_or(0);
                        pb::AssetRef { id, blake3, size }
                    })
                    .collect(),
                catalog_blake3: self.0.catalog_blake3.clone(),
            })
            .collect();
        Ok(Response::new(pb::LeaseTasksResponse { tasks }))
    }

    async fn heartbeat(
        &self,
        req: Request<pb::HeartbeatRequest>,
    ) -> Result<Response<pb::HeartbeatResponse>, Status> {
        let req = req.into_inner();
        let ids: Vec<String> = req.leases.into_iter().map(|l| l.lease_id).collect();
        let now = now_unix();
        if req.draining {
            self.0.scheduler.worker_draining(&req.worker_id, now);
        }
        let (lost, deadline) = self.0.scheduler.heartbeat(&req.worker_id, &ids, now)?;
        Ok(Response::new(pb::HeartbeatResponse {
            lost_leases: lost,
            deadline_unix: deadline,
        }))
    }

    async fn upload_sample(
        &self,
        req: Request<Streaming<pb::UploadChunk>>,
    ) -> Result<Response<pb::UploadSampleResponse>, Status> {
        let mut stream = req.into_inner();
        let header =
            match stream.message().await? {
                Some(pb::UploadChunk {
                    kind: Some(pb::upload_chunk::Kind::Header(h)),
                }) => h,
                _ => return Err(Status::invalid_argument(
                    "an upload starts with its header (worker, lease, job, index, size, blake3)",
                )),
            };
        if header.size > self.0.max_upload_bytes {
            self.0.metrics.rejected_uploads.inc();
            return Err(CoordError::TooLarge(format!(
                "sample {} of {} is {} bytes; this coordinator accepts at most {} (--max-upload-mb)",
                header.index, header.job_id, header.size, self.0.max_upload_bytes
            ))
            .into());
        }
        if !lightfarm_store::is_hash(&header.blake3) {
            return Err(Status::invalid_argument(format!(
                "header blake3 `{}` is not 64 lower-case hex characters",
                header.blake3
            )));
        }
        let check = self.0.scheduler.check_upload(
            &header.worker_id,
            &header.lease_id,
            &header.job_id,
            header.index,
        )?;
        let (split, sample_json) = match check {
            UploadCheck::AlreadyCommitted => {
                // Drain so the client sees a clean end of stream, then acknowledge.
                while stream.message().await?.is_some() {}
                self.0.metrics.duplicate_uploads.inc();
                let existing = self
                    .0
                    .scheduler
                    .samples()
                    .get(&header.job_id, header.index)
                    .map_err(store)?;
                return Ok(Response::new(pb::UploadSampleResponse {
                    committed: false,
                    blake3: existing.map(|r| r.blake3).unwrap_or_default(),
                }));
            }
            UploadCheck::Accept { split, sample_json } => (split, sample_json),
        };
        let mut writer = self.0.blobs.begin().map_err(store)?;
        while let Some(chunk) = stream.message().await? {
            match chunk.kind {
                Some(pb::upload_chunk::Kind::Data(bytes)) => {
                    if writer.written() + bytes.len() as u64 > header.size {
                        self.0.metrics.rejected_uploads.inc();
                        return Err(CoordError::TooLarge(format!(
                            "upload of sample {} sends more than the {} bytes its header declared",
                            header.index, header.size
                        ))
                        .into());
                    }
                    writer.write(&bytes).map_err(store)?;
                }
                _ => {
                    return Err(Status::invalid_argument(
                        "only data chunks may follow the header",
                    ))
                }
            }
        }
        // Verifies size and hash; on mismatch nothing is stored.
        let blake3 = writer.finish(header.size, &header.blake3).map_err(|e| {
            self.0.metrics.rejected_uploads.inc();
            Status::from(CoordError::from(e))
        })?;
        // The sample JSON is ours (from the spec); the worker's statistics are checked to be
        // JSON before they are embedded, and replaced by null otherwise.
        let stats = serde_json::value::RawValue::from_string(header.stats_json.clone())
            .map(|r| r.get().to_owned())
            .unwrap_or_else(|_| "null".into());
        let metadata = format!(
            r#"{{"sample":{sample_json},"stats":{stats},"worker":{},"lease":{}}}"#,
            serde_json::Value::String(header.worker_id.clone()),
            serde_json::Value::String(header.lease_id.clone()),
        );
        let now = now_unix();
        let outcome = self
            .0
            .scheduler
            .samples()
            .commit(
                &header.job_id,
                header.index,
                &split,
                &blake3,
                header.size,
                &metadata,
                now,
            )
            .map_err(store)?;
        let committed = matches!(outcome, CommitOutcome::Committed(_));
        if committed {
            self.0.metrics.committed.inc();
            self.0
                .scheduler
                .mark_done(&header.job_id, header.index, &header.worker_id, now)?;
        } else {
            // A concurrent upload of the same sample won the commit and counted it as done.
            self.0.metrics.duplicate_uploads.inc();
        }
        self.0
            .durable
            .sync()
            .await
            .map_err(|e| Status::internal(format!("making the commit durable: {e}")))?;
        Ok(Response::new(pb::UploadSampleResponse {
            committed,
            blake3,
        }))
    }

    async fn fail_task(
        &self,
        req: Request<pb::FailTaskRequest>,
    ) -> Result<Response<pb::FailTaskResponse>, Status> {
        let req = req.into_inner();
        let retry =
            self.0
                .scheduler
                .fail(&req.worker_id, &req.lease_id, &req.reason, now_unix())?;
        self.0.metrics.task_failures.inc();
        Ok(Response::new(pb::FailTaskResponse { will_retry: retry }))
    }

    type FetchAssetStream = BoxStream<pb::AssetChunk>;

    async fn fetch_asset(
        &self,
        req: Request<pb::FetchAssetRequest>,
    ) -> Result<Response<Self::FetchAssetStream>, Status> {
        let hash = req.into_inner().blake3;
        // Only catalog files may be fetched, never sample blobs by guessing hashes.
        if !self.0.assets.contains_key(&hash) {
            return Err(Status::not_found(format!(
                "no asset with blake3 {hash} in this coordinator's catalog"
            )));
        }
        stream_blob(self.0.blobs.clone(), hash, |data, total| pb::AssetChunk {
            data,
            total_size: total,
        })
    }
}
