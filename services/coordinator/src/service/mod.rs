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
use crate::scheduler::{JobStatus, RunState, Scheduler, UploadCheck, WorkerHello};

mod jobs;
mod samples;
mod workers;

pub use jobs::JobsService;
pub use samples::SamplesService;
pub use workers::WorkersService;

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
