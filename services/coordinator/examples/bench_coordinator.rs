//! Lease + commit throughput of the coordinator with many simulated workers that do no
//! rendering: each leases a few tasks, uploads a small unique blob for each (checksummed,
//! committed exactly once, flushed before the acknowledgement, as real uploads are), repeats.
//!
//! usage: cargo run --release -p lightfarm-coordinator --example bench_coordinator -- [WORKERS] [TASKS] [CAPACITY]
//!
//! Prints tasks/s, and as a same-run reference the rate of plain unary gRPC calls (GetJob) on
//! the same server, so the figure can be read on other machines.

use std::sync::Arc;
use std::time::Instant;

use lightfarm_coordinator::{Coordinator, CoordinatorConfig};
use lightfarm_proto::v1 as pb;
use lightfarm_scene::Catalog;
use tonic::metadata::MetadataValue;
use tonic::Request;

const TOKEN: &str = "bench";

fn authed<T>(msg: T) -> Request<T> {
    let mut r = Request::new(msg);
    let v: MetadataValue<_> = format!("Bearer {TOKEN}").parse().expect("ascii token");
    r.metadata_mut().insert("authorization", v);
    r
}

#[tokio::main(flavor = "multi_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let workers = args.first().copied().unwrap_or(200);
    let tasks = args.get(1).copied().unwrap_or(20_000);
    let capacity = args.get(2).copied().unwrap_or(4) as u32;

    let dir = tempfile::tempdir()?;
    let mut config =
        CoordinatorConfig::new(dir.path().join("data"), TOKEN.into(), Catalog::builtin()?);
    config.lease_seconds = 600.0;
    let coordinator = tokio::task::spawn_blocking(move || Coordinator::open(config)).await??;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = format!("http://{}", listener.local_addr()?);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(coordinator.serve(listener, async {
        let _ = stop_rx.await;
    }));

    let channel = tonic::transport::Endpoint::from_shared(addr.clone())?
        .connect()
        .await?;
    let mut jobs = pb::jobs_client::JobsClient::new(channel.clone());
    let spec = format!("name = \"bench\"\ncount = {tasks}\nwidth = 8\nheight = 8\nspp = 1\n");
    let t = Instant::now();
    let job = jobs
        .submit_dataset(authed(pb::SubmitDatasetRequest {
            spec: Some(pb::submit_dataset_request::Spec::Toml(spec)),
            priority: 0,
        }))
        .await?
        .into_inner();
    eprintln!(
        "submitted {} tasks in {:.2} s",
        tasks,
        t.elapsed().as_secs_f64()
    );

    // Reference: plain unary calls on the same server, same concurrency.
    let calls = 20_000u64;
    let t = Instant::now();
    let mut handles = Vec::new();
    for _ in 0..workers {
        let mut c = pb::jobs_client::JobsClient::new(channel.clone());
        let id = job.id.clone();
        let n = calls / workers;
        handles.push(tokio::spawn(async move {
            for _ in 0..n {
                c.get_job(authed(pb::JobRef { job_id: id.clone() })).await?;
            }
            Ok::<_, tonic::Status>(())
        }));
    }
    for h in handles {
        h.await??;
    }
    let unary_rate = (calls / workers * workers) as f64 / t.elapsed().as_secs_f64();

    let committed = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let t = Instant::now();
    let mut handles = Vec::new();
    for w in 0..workers {
        let mut c = pb::workers_client::WorkersClient::new(channel.clone());
        let committed = committed.clone();
        handles.push(tokio::spawn(async move {
            let name = format!("sim-{w}");
            c.register_worker(authed(pb::RegisterWorkerRequest {
                name: name.clone(),
                ..Default::default()
            }))
            .await?;
            loop {
                let leased = c
                    .lease_tasks(authed(pb::LeaseTasksRequest {
                        worker_id: name.clone(),
                        capacity,
                        cached_assets: vec![],
                    }))
                    .await?
                    .into_inner()
                    .tasks;
                if leased.is_empty() {
                    return Ok::<_, tonic::Status>(());
                }
                for task in leased {
                    let body = format!("sample {} of {}", task.index, task.job_id).into_bytes();
                    let header = pb::UploadHeader {
                        worker_id: name.clone(),
                        lease_id: task.lease_id.clone(),
                        job_id: task.job_id.clone(),
                        index: task.index,
                        size: body.len() as u64,
                        blake3: blake3::hash(&body).to_hex().to_string(),
                        stats_json: "{}".into(),
                    };
                    let msgs = vec![
                        pb::UploadChunk {
                            kind: Some(pb::upload_chunk::Kind::Header(header)),
                        },
                        pb::UploadChunk {
                            kind: Some(pb::upload_chunk::Kind::Data(body)),
                        },
                    ];
                    let r = c
                        .upload_sample(authed(tokio_stream::iter(msgs)))
                        .await?
                        .into_inner();
                    if r.committed {
                        committed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    }
                }
            }
        }));
    }
    for h in handles {
        h.await??;
    }
    let seconds = t.elapsed().as_secs_f64();
    let done = committed.load(std::sync::atomic::Ordering::Relaxed);
    let final_job = jobs
        .get_job(authed(pb::JobRef {
            job_id: job.id.clone(),
        }))
        .await?
        .into_inner();
    let _ = stop_tx.send(());
    server.await??;

    let rate = done as f64 / seconds;
    println!(
        "workers {workers}, capacity {capacity}, tasks {tasks}: committed {done} in {seconds:.2} s"
    );
    println!(
        "lease+commit: {rate:.0} tasks/s  (target 5000: {:.2}x)",
        rate / 5000.0
    );
    println!("reference, unary GetJob on the same server: {unary_rate:.0} calls/s  (tasks/s per call/s: {:.3})", rate / unary_rate);
    println!(
        "job state {:?}, counts {:?}",
        pb::JobState::try_from(final_job.state),
        final_job.counts
    );
    if done != tasks {
        return Err(format!("{done} of {tasks} tasks committed").into());
    }
    Ok(())
}
