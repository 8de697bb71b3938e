//! The gRPC handlers: thin translations between `lightfarm_proto` and the [`Scheduler`] and
//! the store.

use std::pin::Pin;
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use lightfarm_proto::v1 as pb;
use lightfarm_store::{BlobStore, CommitOutcome, SampleRecord};
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};

use crate::error::CoordError;
use crate::metrics::Metrics;
use crate::scheduler::{JobStatus, RunState, Scheduler, UploadCheck};

/// Bytes per streamed chunk (gRPC's default message limit is 4 MiB).
pub const CHUNK: usize = 1 << 20;

pub fn now_unix() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

/// Shared by the three services.
pub struct Shared {
    pub scheduler: Arc<Scheduler>,
    pub blobs: Arc<dyn BlobStore>,
    pub metrics: Arc<Metrics>,
    pub max_upload_bytes: u64,
    pub heartbeat_seconds: u32,
    /// Assets by BLAKE3 a worker may fetch (the catalog's files, imported at start), with
    /// their sizes.
    pub assets: std::collections::HashMap<String, u64>,
    /// BLAKE3 of the catalog file itself (workers fetch it to resolve ids to files).
    pub catalog_blake3: String,
    /// Waited on before a commit is acknowledged: an acknowledged sample survives kill -9
    /// and power loss.
    pub durable: crate::durability::GroupSync,
}

pub fn job_to_pb(s: &JobStatus) -> pb::Job {
    let state = match s.record.run {
        RunState::Cancelled => pb::JobState::Cancelled,
        _ if s.done >= s.record.count => pb::JobState::Completed,
        _ if s.done + s.failed >= s.record.count => pb::JobState::Failed,
        RunState::Paused => pb::JobState::Paused,
        RunState::Running => pb::JobState::Running,
    };
    pb::Job {
        id: s.record.id.clone(),
        name: s.record.name.clone(),
        state: state as i32,
        priority: s.record.priority,
        count: s.record.count,
        counts: Some(pb::TaskCounts {
            queued: s.queued,
            leased: s.leased,
            done: s.done,
            failed: s.failed,
        }),
        spec_toml: s.record.spec_toml.clone(),
        created_unix: s.record.created_unix,
        samples_per_second: s.samples_per_second,
        eta_seconds: s.eta_seconds,
        failures: s
            .recent_failures
            .iter()
            .map(|(index, f)| pb::TaskFailure {
                index: *index,
                worker_id: f.worker.clone(),
                reason: f.reason.clone(),
                at_unix: f.at_unix,
            })
            .collect(),
    }
}

fn record_to_pb(r: &SampleRecord) -> pb::SampleInfo {
    pb::SampleInfo {
        job_id: r.job_id.clone(),
        index: r.index,
        split: r.split.clone(),
        blake3: r.blake3.clone(),
        size: r.size,
        metadata_json: r.metadata_json.clone(),
        committed_unix: r.committed_unix,
        sequence: r.sequence,
    }
}

/// The reverse of [`record_to_pb`], for clients rebuilding index records from a stream.
pub fn record_from_pb(i: pb::SampleInfo) -> SampleRecord {
    SampleRecord {
        job_id: i.job_id,
        index: i.index,
        split: i.split,
        blake3: i.blake3,
        size: i.size,
        metadata_json: i.metadata_json,
        committed_unix: i.committed_unix,
        sequence: i.sequence,
    }
}

/// Reassembles a `GetSample` / `StreamSamples` stream into whole samples as store records.
#[derive(Default)]
pub struct SampleAssembler(lightfarm_proto::client::SampleChunks);

impl SampleAssembler {
    /// Feeds one chunk; returns the previous sample when this chunk starts the next one.
    pub fn push(
        &mut self,
        chunk: pb::SampleChunk,
    ) -> Result<Option<(SampleRecord, Vec<u8>)>, String> {
        Ok(self.0.push(chunk)?.map(|(i, d)| (record_from_pb(i), d)))
    }

    /// The last sample, once the stream has ended.
    pub fn finish(self) -> Option<(SampleRecord, Vec<u8>)> {
        self.0.finish().map(|(i, d)| (record_from_pb(i), d))
    }
}

/// Store errors as gRPC statuses (through the coordinator's one mapping).
fn store(e: lightfarm_store::StoreError) -> Status {
    CoordError::from(e).into()
}

fn opt(s: &str) -> Option<&str> {
    (!s.is_empty()).then_some(s)
}

// ---------------------------------------------------------------- Jobs

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

// ---------------------------------------------------------------- Workers

pub struct WorkersService(pub Arc<Shared>);

#[tonic::async_trait]
impl pb::workers_server::Workers for WorkersService {
    async fn register_worker(
        &self,
        req: Request<pb::RegisterWorkerRequest>,
    ) -> Result<Response<pb::RegisterWorkerResponse>, Status> {
        let req = req.into_inner();
        let id = self
            .0
            .scheduler
            .register_worker(&req.name, req.cached_assets)?;
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
        let (lost, deadline) = self
            .0
            .scheduler
            .heartbeat(&req.worker_id, &ids, now_unix())?;
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
        } else {
            self.0.metrics.duplicate_uploads.inc();
        }
        self.0
            .scheduler
            .mark_done(&header.job_id, header.index, now)?;
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

/// Streams a blob in `CHUNK`s from a blocking reader thread.
fn stream_blob<T: Send + 'static>(
    blobs: Arc<dyn BlobStore>,
    hash: String,
    make: fn(Vec<u8>, u64) -> T,
) -> Result<Response<BoxStream<T>>, Status> {
    let total = blobs
        .size(&hash)
        .map_err(store)?
        .ok_or_else(|| Status::not_found(format!("blob {hash} is missing")))?;
    let mut reader = blobs.open(&hash).map_err(store)?;
    let (tx, rx) = mpsc::channel(4);
    tokio::task::spawn_blocking(move || {
        let mut first = true;
        loop {
            let mut buf = vec![0u8; CHUNK];
            let n = match std::io::Read::read(&mut reader, &mut buf) {
                Ok(n) => n,
                Err(e) => {
                    let _ = tx
                        .blocking_send(Err(Status::internal(format!("reading blob {hash}: {e}"))));
                    return;
                }
            };
            if n == 0 && !first {
                return;
            }
            buf.truncate(n);
            if tx
                .blocking_send(Ok(make(buf, if first { total } else { 0 })))
                .is_err()
                || n == 0
            {
                return;
            }
            first = false;
        }
    });
    Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
}

// ---------------------------------------------------------------- Samples

pub struct SamplesService(pub Arc<Shared>);

fn sample_chunks(
    blobs: &dyn BlobStore,
    record: &SampleRecord,
    metadata_only: bool,
) -> Result<Vec<pb::SampleChunk>, Status> {
    let mut out = vec![pb::SampleChunk {
        kind: Some(pb::sample_chunk::Kind::Info(record_to_pb(record))),
    }];
    if !metadata_only {
        let bytes = blobs.read(&record.blake3).map_err(store)?;
        out.extend(bytes.chunks(CHUNK).map(|c| pb::SampleChunk {
            kind: Some(pb::sample_chunk::Kind::Data(c.to_vec())),
        }));
    }
    Ok(out)
}

#[tonic::async_trait]
impl pb::samples_server::Samples for SamplesService {
    async fn list_samples(
        &self,
        req: Request<pb::ListSamplesRequest>,
    ) -> Result<Response<pb::ListSamplesResponse>, Status> {
        let req = req.into_inner();
        let limit = if req.limit == 0 {
            1000
        } else {
            req.limit.min(10_000)
        } as usize;
        let (records, total) = self
            .0
            .scheduler
            .samples()
            .list(opt(&req.job_id), opt(&req.split), req.offset, limit)
            .map_err(store)?;
        Ok(Response::new(pb::ListSamplesResponse {
            samples: records.iter().map(record_to_pb).collect(),
            total,
        }))
    }

    type GetSampleStream = BoxStream<pb::SampleChunk>;

    async fn get_sample(
        &self,
        req: Request<pb::GetSampleRequest>,
    ) -> Result<Response<Self::GetSampleStream>, Status> {
        let req = req.into_inner();
        let record = self
            .0
            .scheduler
            .samples()
            .get(&req.job_id, req.index)
            .map_err(store)?
            .ok_or_else(|| {
                Status::not_found(format!(
                    "sample {} of job {} is not committed",
                    req.index, req.job_id
                ))
            })?;
        let chunks = sample_chunks(self.0.blobs.as_ref(), &record, false)?;
        Ok(Response::new(Box::pin(tokio_stream::iter(
            chunks.into_iter().map(Ok),
        ))))
    }

    type StreamSamplesStream = BoxStream<pb::SampleChunk>;

    async fn stream_samples(
        &self,
        req: Request<pb::StreamSamplesRequest>,
    ) -> Result<Response<Self::StreamSamplesStream>, Status> {
        let req = req.into_inner();
        let shared = self.0.clone();
        let mut commits = shared.scheduler.samples().subscribe();
        let (tx, rx) = mpsc::channel(8);
        tokio::spawn(async move {
            let mut cursor = req.cursor;
            loop {
                let batch = match shared.scheduler.samples().since(
                    cursor,
                    opt(&req.job_id),
                    opt(&req.split),
                    64,
                ) {
                    Ok(b) => b,
                    Err(e) => {
                        let _ = tx.send(Err(CoordError::from(e).into())).await;
                        return;
                    }
                };
                for record in &batch {
                    cursor = record.sequence + 1;
                    let chunks =
                        match sample_chunks(shared.blobs.as_ref(), record, req.metadata_only) {
                            Ok(c) => c,
                            Err(e) => {
                                let _ = tx.send(Err(e)).await;
                                return;
                            }
                        };
                    for c in chunks {
                        if tx.send(Ok(c)).await.is_err() {
                            return;
                        }
                    }
                }
                if batch.is_empty() {
                    if !req.follow {
                        return;
                    }
                    if commits.changed().await.is_err() {
                        return;
                    }
                }
            }
        });
        let stream = ReceiverStream::new(rx).map(|x| x);
        Ok(Response::new(Box::pin(stream)))
    }
}
