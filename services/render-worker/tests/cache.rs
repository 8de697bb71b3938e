//! The asset cache against a fake coordinator whose FetchAsset streams whatever bytes the test
//! chooses: a transfer whose BLAKE3 differs from the requested hash (one flipped byte, a
//! truncated stream) is refused and leaves nothing in the cache, the right bytes are kept
//! exactly, and a malformed hash is refused before anything is fetched.

use std::path::Path;
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use lightfarm_proto::v1 as pb;
use lightfarm_worker::{AssetCache, Client};
use tonic::{Request, Response, Status, Streaming};

const TOKEN: &str = "cache-token";

/// What FetchAsset answers with, and how often it was asked.
#[derive(Clone, Default)]
struct Fake {
    serve: Arc<Mutex<Vec<u8>>>,
    fetches: Arc<AtomicUsize>,
}

type BoxStream<T> = Pin<Box<dyn tokio_stream::Stream<Item = Result<T, Status>> + Send>>;

#[tonic::async_trait]
impl pb::workers_server::Workers for Fake {
    async fn register_worker(
        &self,
        _: Request<pb::RegisterWorkerRequest>,
    ) -> Result<Response<pb::RegisterWorkerResponse>, Status> {
        Err(Status::unimplemented("fake coordinator"))
    }

    async fn lease_tasks(
        &self,
        _: Request<pb::LeaseTasksRequest>,
    ) -> Result<Response<pb::LeaseTasksResponse>, Status> {
        Err(Status::unimplemented("fake coordinator"))
    }

    async fn heartbeat(
        &self,
        _: Request<pb::HeartbeatRequest>,
    ) -> Result<Response<pb::HeartbeatResponse>, Status> {
        Err(Status::unimplemented("fake coordinator"))
    }

    async fn upload_sample(
        &self,
        _: Request<Streaming<pb::UploadChunk>>,
    ) -> Result<Response<pb::UploadSampleResponse>, Status> {
        Err(Status::unimplemented("fake coordinator"))
    }

    async fn fail_task(
        &self,
        _: Request<pb::FailTaskRequest>,
    ) -> Result<Response<pb::FailTaskResponse>, Status> {
        Err(Status::unimplemented("fake coordinator"))
    }

    type FetchAssetStream = BoxStream<pb::AssetChunk>;

    async fn fetch_asset(
        &self,
        _: Request<pb::FetchAssetRequest>,
    ) -> Result<Response<Self::FetchAssetStream>, Status> {
        self.fetches.fetch_add(1, Ordering::SeqCst);
        let bytes = self.serve.lock().expect("fake state").clone();
        let total = bytes.len() as u64;
        // Several chunks, so the cache has to reassemble them.
        let chunks: Vec<Result<pb::AssetChunk, Status>> = bytes
            .chunks(1000)
            .enumerate()
            .map(|(i, c)| {
                Ok(pb::AssetChunk {
                    data: c.to_vec(),
                    total_size: if i == 0 { total } else { 0 },
                })
            })
            .collect();
        Ok(Response::new(Box::pin(tokio_stream::iter(chunks))))
    }
}

/// Starts the fake on an ephemeral port; returns its address.
async fn serve(fake: Fake) -> String {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = format!("http://{}", listener.local_addr().expect("addr"));
    tokio::spawn(
        tonic::transport::Server::builder()
            .add_service(pb::workers_server::WorkersServer::new(fake))
            .serve_with_incoming(tokio_stream::wrappers::TcpListenerStream::new(listener)),
    );
    addr
}

/// Files under `dir`, recursively (nothing that should not be in the cache may hide there).
fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).expect("read dir").flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// `ensure`, bounded: a refused transfer must end, not retry for ever.
async fn ensure(cache: &AssetCache, client: &Client, hash: &str) -> anyhow::Result<()> {
    tokio::time::timeout(Duration::from_secs(30), cache.ensure(client, hash))
        .await
        .expect("ensure ends promptly instead of retrying")
        .map(|_| ())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn corrupt_transfers_are_refused_and_good_ones_kept_exactly() {
    let good: Vec<u8> = (0..5000u32).map(|i| (i * 31 % 251) as u8).collect();
    let hash = blake3::hash(&good).to_hex().to_string();
    let mut flipped = good.clone();
    flipped[2345] ^= 0x10;
    let truncated = good[..3000].to_vec();

    let fake = Fake::default();
    let addr = serve(fake.clone()).await;
    let (_stop_tx, stop) = tokio::sync::watch::channel(false);
    let client = Client::connect(&addr, TOKEN, None, stop)
        .await
        .expect("client");
    let dir = tempfile::tempdir().expect("tmp");
    let root = dir.path().join("assets");
    let cache = AssetCache::open(&root).expect("cache");

    for (what, bytes) in [("one flipped byte", &flipped), ("truncated", &truncated)] {
        *fake.serve.lock().expect("fake state") = bytes.clone();
        let before = fake.fetches.load(Ordering::SeqCst);
        let e = ensure(&cache, &client, &hash)
            .await
            .expect_err("a corrupt transfer is refused");
        let msg = format!("{e:#}");
        assert!(
            msg.contains(&hash) && msg.contains("corrupt"),
            "{what}: the error names the hash and says corrupt: {msg}"
        );
        assert!(
            fake.fetches.load(Ordering::SeqCst) > before,
            "{what}: the asset was fetched"
        );
        assert!(
            cache.hashes().expect("hashes").is_empty(),
            "{what}: nothing cached"
        );
        let left = files(&root);
        assert!(left.is_empty(), "{what}: files left in the cache: {left:?}");
    }

    *fake.serve.lock().expect("fake state") = good.clone();
    ensure(&cache, &client, &hash)
        .await
        .expect("the right bytes are accepted");
    assert_eq!(cache.hashes().expect("hashes"), vec![hash.clone()]);
    let blob = root.join("blobs").join(&hash);
    assert_eq!(
        std::fs::read(&blob).expect("blob"),
        good,
        "blob holds the bytes"
    );
    assert_eq!(files(&root), vec![blob], "only the blob, nothing in tmp/");

    // Cached now: a second ensure does not fetch again, even if the coordinator went bad.
    *fake.serve.lock().expect("fake state") = flipped;
    let before = fake.fetches.load(Ordering::SeqCst);
    ensure(&cache, &client, &hash).await.expect("cached");
    assert_eq!(fake.fetches.load(Ordering::SeqCst), before, "no refetch");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_hashes_are_refused_before_any_fetch() {
    let fake = Fake::default();
    *fake.serve.lock().expect("fake state") = b"anything".to_vec();
    let addr = serve(fake.clone()).await;
    let (_stop_tx, stop) = tokio::sync::watch::channel(false);
    let client = Client::connect(&addr, TOKEN, None, stop)
        .await
        .expect("client");
    let dir = tempfile::tempdir().expect("tmp");
    let root = dir.path().join("assets");
    let cache = AssetCache::open(&root).expect("cache");
    let upper = blake3::hash(b"anything").to_hex().to_uppercase();
    for bad in [
        "",
        "../../etc/passwd",
        &"a".repeat(63),
        &"a".repeat(65),
        &"g".repeat(64),
        upper.as_str(),
    ] {
        let e = ensure(&cache, &client, bad)
            .await
            .expect_err("a malformed hash is refused");
        let msg = format!("{e:#}");
        assert!(
            msg.contains("not a BLAKE3"),
            "{bad:?}: the error says why: {msg}"
        );
    }
    assert_eq!(
        fake.fetches.load(Ordering::SeqCst),
        0,
        "nothing was fetched"
    );
    assert!(files(&root).is_empty(), "nothing written");
}
