//! The coordinator over gRPC on an ephemeral port, in process: a dataset rendered by two
//! in-process workers is committed exactly once and exports EXRs holding exactly the rendered
//! passes; bad input gets clear status codes and leaves nothing half-written.

use std::time::{Duration, Instant};

use lightfarm_coordinator::{Coordinator, CoordinatorConfig};
use lightfarm_proto::v1 as pb;
use lightfarm_scene::Catalog;
use tonic::Code;

const TOKEN: &str = "test-token";

const SPEC: &str = r#"
name = "grpc-test"
seed = 5
count = 6
width = 16
height = 16
spp = 1
[subject]
hair_styles = ["buzz"]
glasses_probability = 0.5
"#;

struct Running {
    addr: String,
    port: u16,
    metrics_addr: std::net::SocketAddr,
    /// Holds the sled db open: take it and drop it before the data directory is reopened.
    scheduler: Option<std::sync::Arc<lightfarm_coordinator::scheduler::Scheduler>>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    handle: tokio::task::JoinHandle<()>,
    dir: tempfile::TempDir,
}

/// A coordinator on an ephemeral port (and /metrics on another), with its data in a temp dir;
/// `configure` adjusts the config and may write files into that dir first.
async fn start(configure: impl FnOnce(&std::path::Path, &mut CoordinatorConfig)) -> Running {
    let dir = tempfile::tempdir().expect("tmp");
    let mut config = CoordinatorConfig::new(
        dir.path().join("data"),
        TOKEN.into(),
        Catalog::builtin().expect("catalog"),
    );
    configure(dir.path(), &mut config);
    let coordinator = tokio::task::spawn_blocking(move || Coordinator::open(config))
        .await
        .expect("join")
        .expect("open");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let addr = format!("http://127.0.0.1:{port}");
    let metrics_listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let metrics_addr = metrics_listener.local_addr().expect("addr");
    // /metrics stops with the gRPC server: its handle on the scheduler keeps the sled db (and
    // its lock) open, and a test reopens the data directory after `handle` finishes.
    let (metrics_stop, metrics_stopped) = tokio::sync::oneshot::channel::<()>();
    let board = coordinator
        .dashboard(&lightfarm_coordinator::dashboard::DashboardConfig {
            token: TOKEN.into(),
            secure_cookies: false,
            trainer: None,
        })
        .expect("dashboard");
    let tls = coordinator.metrics_tls().expect("metrics TLS");
    let scheduler = coordinator.scheduler().clone();
    let metrics_server = tokio::spawn(lightfarm_coordinator::metrics::serve_metrics(
        metrics_listener,
        coordinator.metrics().clone(),
        coordinator.scheduler().clone(),
        Some(board),
        tls,
        async {
            let _ = metrics_stopped.await;
        },
    ));
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let handle = tokio::spawn(async move {
        coordinator
            .serve(listener, async {
                let _ = rx.await;
            })
            .await
            .expect("serve");
        let _ = metrics_stop.send(());
        metrics_server
            .await
            .expect("metrics join")
            .expect("metrics server");
    });
    Running {
        addr,
        port,
        metrics_addr,
        scheduler: Some(scheduler),
        stop: Some(tx),
        handle,
        dir,
    }
}

type Authed = lightfarm_worker::client::AuthedChannel;

fn clients(
    addr: &str,
    token: &str,
) -> (
    pb::jobs_client::JobsClient<Authed>,
    pb::workers_client::WorkersClient<Authed>,
    pb::samples_client::SamplesClient<Authed>,
) {
    let (ch, auth) = lightfarm_worker::client::channel(addr, token, None).expect("channel");
    (
        pb::jobs_client::JobsClient::with_interceptor(ch.clone(), auth.clone()),
        pb::workers_client::WorkersClient::with_interceptor(ch.clone(), auth.clone()),
        pb::samples_client::SamplesClient::with_interceptor(ch, auth)
            .max_decoding_message_size(64 << 20),
    )
}

/// Opens the coordinator of `data_dir` again. The stopped one's aborted background tasks let go
/// of the sled lock a moment after `serve` returns, so opening is retried for a while.
async fn reopen(data_dir: &std::path::Path) -> Coordinator {
    let catalog = Catalog::builtin().expect("catalog");
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let config = CoordinatorConfig::new(data_dir.to_path_buf(), TOKEN.into(), catalog.clone());
        let opened = tokio::task::spawn_blocking(move || Coordinator::open(config))
            .await
            .expect("join");
        match opened {
            Ok(c) => return c,
            Err(_) if Instant::now() < deadline => {
                tokio::time::sleep(Duration::from_millis(100)).await
            }
            Err(e) => panic!("reopening {}: {e}", data_dir.display()),
        }
    }
}

/// Renders sample `index` of `SPEC` in this process, as a worker would.
fn render_here(
    renderer: &lightfarm_render::Renderer,
    catalog: &Catalog,
    resolved: &lightfarm_scene::spec::ResolvedSpec,
    index: u64,
) -> lightfarm_render::RenderOutput {
    let sample = lightfarm_scene::expand::expand(resolved, index).expect("expand");
    let assembled = lightfarm_subject::assemble(&sample, catalog).expect("assemble");
    lightfarm_subject::render::render_sample(renderer, &assembled, &mut |_| {}).expect("render")
}

/// Decodes `exr` with the exr crate alone, channel by channel by name, and asserts that the
/// channels are exactly the passes of `want` and every value is bit-identical. Nothing of
/// lightfarm's own EXR code is involved, so a writer that swapped or mislabelled a pass (or
/// wrote it at lower precision) fails here.
fn assert_exr_holds(exr: &[u8], want: &lightfarm_render::RenderOutput, what: &str) {
    use exr::prelude::{FlatSamples, ReadChannels, ReadLayers};
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(exr))
        .expect("decodes as EXR");
    assert_eq!(img.layer_data.len(), 1, "{what}: one layer");
    let layer = &img.layer_data[0];
    let (w, h) = (want.width as usize, want.height as usize);
    assert_eq!((layer.size.0, layer.size.1), (w, h), "{what}: size");
    let got: std::collections::BTreeMap<String, &Vec<f32>> = layer
        .channel_data
        .list
        .iter()
        .map(|c| match &c.sample_data {
            FlatSamples::F32(v) => (c.name.to_string(), v),
            _ => panic!("{what}: channel {} is not 32-bit float", c.name),
        })
        .collect();
    let mut expected: Vec<(String, Vec<f32>)> = Vec::new();
    let mut split3 = |layer: &str, names: [&str; 3], px: &[[f32; 3]]| {
        for (k, n) in names.iter().enumerate() {
            expected.push((format!("{layer}.{n}"), px.iter().map(|p| p[k]).collect()));
        }
    };
    for (l, lit) in want.lit.iter().enumerate() {
        split3(&format!("lit{l}"), ["R", "G", "B"], lit);
    }
    split3("albedo", ["R", "G", "B"], &want.albedo);
    split3("normal", ["X", "Y", "Z"], &want.normal);
    split3("normal_lens", ["X", "Y", "Z"], &want.normal_lens);
    // The dataset's appendix passes (the spec's default set).
    for (l, lp) in want.passes.iter().enumerate() {
        for p in &want.pass_set {
            if let Some(img) = lp.rgb(*p) {
                split3(&format!("{}{l}", p.name()), ["R", "G", "B"], img);
            }
        }
    }
    expected.push(("mask.A".into(), want.mask.clone()));
    for (l, lp) in want.passes.iter().enumerate() {
        if want
            .pass_set
            .contains(&lightfarm_render::passes::Pass::Shadow)
        {
            expected.push((format!("shadow{l}.A"), lp.shadow.clone()));
        }
    }
    if want.pass_set.contains(&lightfarm_render::passes::Pass::Id) {
        expected.push(("id.A".into(), want.id.iter().map(|v| *v as f32).collect()));
    }

    let mut names: Vec<&String> = expected.iter().map(|(n, _)| n).collect();
    names.sort();
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        names,
        "{what}: channel names"
    );
    for (name, values) in &expected {
        assert_eq!(values.len(), w * h, "{what}: {name} rendered size");
        let decoded = got[name];
        assert_eq!(decoded.len(), w * h, "{what}: {name} decoded size");
        if let Some(i) = (0..w * h).find(|&i| decoded[i].to_bits() != values[i].to_bits()) {
            panic!(
                "{what}: {name} at pixel ({}, {}) is {} in the EXR, {} rendered",
                i % w,
                i / w,
                decoded[i],
                values[i]
            );
        }
    }
}

async fn submit(jobs: &mut pb::jobs_client::JobsClient<Authed>, spec: &str) -> pb::Job {
    jobs.submit_dataset(pb::SubmitDatasetRequest {
        spec: Some(pb::submit_dataset_request::Spec::Toml(spec.into())),
        priority: 0,
    })
    .await
    .expect("submit")
    .into_inner()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_dataset_renders_commits_once_and_exports() {
    let mut c = start(|_, config| config.max_upload_bytes = 256 << 20).await;
    let (mut jobs, _, mut samples) = clients(&c.addr, TOKEN);
    let job = submit(&mut jobs, SPEC).await;
    assert_eq!(job.count, 6);

    let (done_tx, done_rx) = tokio::sync::watch::channel(false);
    let mut workers = Vec::new();
    for name in ["wa", "wb"] {
        let mut rx = done_rx.clone();
        let config = lightfarm_worker::WorkerConfig {
            coordinator: c.addr.clone(),
            token: TOKEN.into(),
            name: name.into(),
            cache_dir: c.dir.path().join(name),
            device: "auto".into(),
            tls_ca: None,
            max_samples: None,
        };
        workers.push(tokio::spawn(lightfarm_worker::run(config, async move {
            let _ = rx.wait_for(|d| *d).await;
        })));
    }
    let mut watch = jobs
        .watch_job(pb::JobRef {
            job_id: job.id.clone(),
        })
        .await
        .expect("watch")
        .into_inner();
    let mut last = None;
    let watched = tokio::time::timeout(Duration::from_secs(600), async {
        while let Some(j) = watch.message().await.expect("watch stream") {
            last = Some(j);
        }
    })
    .await;
    assert!(watched.is_ok(), "job did not finish in time: {last:?}");
    let last = last.expect("updates");
    assert_eq!(last.state, pb::JobState::Completed as i32, "{last:?}");
    let _ = done_tx.send(true);
    for w in workers {
        w.await.expect("join").expect("worker");
    }
    // Both workers said goodbye on the way out; between them they rendered every sample.
    let seen = c
        .scheduler
        .take()
        .expect("scheduler")
        .workers(lightfarm_coordinator::service::now_unix());
    let names: Vec<(&str, &str)> = seen
        .iter()
        .map(|w| (w.name.as_str(), w.state.as_str()))
        .collect();
    assert_eq!(names, [("wa", "stopped"), ("wb", "stopped")]);
    assert_eq!(seen.iter().map(|w| w.rendered).sum::<u64>(), 6);
    assert!(
        seen.iter().all(|w| !w.device.is_empty() && w.failures == 0),
        "{seen:?}"
    );

    // Every index committed exactly once.
    let list = samples
        .list_samples(pb::ListSamplesRequest {
            job_id: job.id.clone(),
            split: String::new(),
            offset: 0,
            limit: 0,
        })
        .await
        .expect("list")
        .into_inner();
    assert_eq!(list.total, 6);
    let mut idx: Vec<u64> = list.samples.iter().map(|s| s.index).collect();
    idx.sort();
    assert_eq!(idx, (0..6).collect::<Vec<_>>());
    let mut seqs: Vec<u64> = list.samples.iter().map(|s| s.sequence).collect();
    seqs.sort();
    seqs.dedup();
    assert_eq!(seqs.len(), 6);

    // Stream everything, export as WebDataset, read it back, decode the EXRs.
    let mut stream = samples
        .stream_samples(pb::StreamSamplesRequest {
            job_id: job.id.clone(),
            split: String::new(),
            cursor: 0,
            follow: false,
            metadata_only: false,
        })
        .await
        .expect("stream")
        .into_inner();
    let out = c.dir.path().join("export");
    let mut writer = lightfarm_store::ExportWriter::create(
        &out,
        &job.id,
        &lightfarm_store::ExportFormat::WebDataset {
            samples_per_shard: 4,
        },
    )
    .expect("writer");
    let mut samples = lightfarm_coordinator::service::SampleAssembler::default();
    while let Some(chunk) = stream.message().await.expect("chunk") {
        if let Some((record, bytes)) = samples.push(chunk).expect("info before data") {
            writer.add(&record, &bytes).expect("add");
        }
    }
    let (record, bytes) = samples.finish().expect("at least one sample");
    writer.add(&record, &bytes).expect("add");
    let report = writer.finish().expect("finish");
    assert_eq!(report.samples, 6);
    let back = lightfarm_store::read_export(&out).expect("read export");
    assert_eq!(back.len(), 6);
    for s in &back {
        assert_eq!(s.json["index"], s.index);
        assert!(s.json["sample"]["head"]["blake3"].is_string());
    }
    // Every exported EXR holds exactly what rendering its sample here gives.
    tokio::task::spawn_blocking(move || {
        let catalog = Catalog::builtin().expect("catalog");
        let resolved = lightfarm_scene::spec::DatasetSpec::from_toml_str(SPEC, "grpc-test.toml")
            .and_then(|s| s.validate(&catalog))
            .expect("spec");
        let renderer =
            lightfarm_render::Renderer::new(&lightfarm_render::vulkan::DeviceRequest::Auto)
                .expect("device");
        for s in &back {
            let want = render_here(&renderer, &catalog, &resolved, s.index);
            let what = format!("sample {}", s.index);
            // Non-trivial, so equality cannot hold between two empty images.
            assert!(
                want.mask.iter().any(|&m| m > 0.0),
                "{what}: subject in view"
            );
            assert_eq!(want.lit.len(), 2, "{what}: two lightings");
            assert_ne!(want.lit[0], want.lit[1], "{what}: lightings differ");
            assert_exr_holds(&s.exr, &want, &what);
        }
    })
    .await
    .expect("pixel check");

    // Prometheus text on /metrics reflects the job.
    let text = http_get(c.metrics_addr, "/metrics").await;
    for line in [
        "lightfarm_samples_committed_total 6",
        "lightfarm_tasks_done 6",
        "lightfarm_tasks_queued 0",
    ] {
        assert!(text.contains(line), "{line} missing in:\n{text}");
    }
    assert!(text.contains("lightfarm_lease_seconds_bucket"));

    let _ = c.stop.take().map(|s| s.send(()));
    c.handle.await.expect("server");

    // The committed total counts this data directory, not this process: a restarted
    // coordinator starts where the last one stopped.
    let reopened = reopen(&c.dir.path().join("data")).await;
    assert_eq!(reopened.metrics().committed.get(), 6, "after a reopen");
    let text = reopened.metrics().render(reopened.scheduler());
    assert!(
        text.contains("lightfarm_samples_committed_total 6"),
        "after a reopen:\n{text}"
    );
}

/// A minimal HTTP/1.1 GET (the test needs no HTTP client crate).
async fn http_get(addr: std::net::SocketAddr, path: &str) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.expect("connect");
    s.write_all(format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").as_bytes())
        .await
        .expect("write");
    let mut buf = String::new();
    s.read_to_string(&mut buf).await.expect("read");
    assert!(buf.starts_with("HTTP/1.1 200"), "{buf}");
    buf
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_input_gets_clear_codes_and_stores_nothing() {
    let mut c = start(|_, config| config.max_upload_bytes = 1 << 20).await;
    // Authentication.
    for token in ["", "wrong"] {
        let (mut jobs, ..) = clients(&c.addr, token);
        let e = jobs
            .list_jobs(pb::ListJobsRequest {})
            .await
            .expect_err("no token");
        assert_eq!(e.code(), Code::Unauthenticated, "{e}");
        assert!(e.message().contains("token"));
    }
    let (mut jobs, mut workers, mut samples) = clients(&c.addr, TOKEN);
    let e = jobs
        .get_job(pb::JobRef {
            job_id: "ghost".into(),
        })
        .await
        .expect_err("unknown job");
    assert_eq!(e.code(), Code::NotFound);
    assert!(e.message().contains("ghost"));
    let e = jobs
        .submit_dataset(pb::SubmitDatasetRequest {
            spec: Some(pb::submit_dataset_request::Spec::Toml(
                "name = \"x\"\ncount = -3\n".into(),
            )),
            priority: 0,
        })
        .await
        .expect_err("bad spec");
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("count"), "{e}");

    let job = submit(&mut jobs, SPEC).await;
    let reg = workers
        .register_worker(pb::RegisterWorkerRequest {
            name: "w".into(),
            ..Default::default()
        })
        .await
        .expect("register")
        .into_inner();
    let task = workers
        .lease_tasks(pb::LeaseTasksRequest {
            worker_id: reg.worker_id.clone(),
            capacity: 1,
            cached_assets: vec![],
        })
        .await
        .expect("lease")
        .into_inner()
        .tasks
        .remove(0);
    let body = vec![7u8; 5000];
    let good = blake3::hash(&body).to_hex().to_string();
    let header = |size: u64, hash: &str, lease: &str, job: &str| pb::UploadChunk {
        kind: Some(pb::upload_chunk::Kind::Header(pb::UploadHeader {
            worker_id: reg.worker_id.clone(),
            lease_id: lease.into(),
            job_id: job.into(),
            index: task.index,
            size,
            blake3: hash.into(),
            stats_json: "{}".into(),
        })),
    };
    let data = |b: &[u8]| pb::UploadChunk {
        kind: Some(pb::upload_chunk::Kind::Data(b.to_vec())),
    };
    let upload = |msgs: Vec<pb::UploadChunk>| {
        let mut w = workers.clone();
        async move { w.upload_sample(tokio_stream::iter(msgs)).await }
    };
    let cases: Vec<(&str, Vec<pb::UploadChunk>, Code)> = vec![
        (
            "checksum mismatch",
            vec![
                header(5000, &"0".repeat(64), &task.lease_id, &job.id),
                data(&body),
            ],
            Code::DataLoss,
        ),
        (
            "truncated stream",
            vec![
                header(5000, &good, &task.lease_id, &job.id),
                data(&body[..2500]),
            ],
            Code::DataLoss,
        ),
        (
            "more than declared",
            vec![header(100, &good, &task.lease_id, &job.id), data(&body)],
            Code::ResourceExhausted,
        ),
        (
            "oversized",
            vec![header(2 << 20, &good, &task.lease_id, &job.id)],
            Code::ResourceExhausted,
        ),
        ("no header", vec![data(&body)], Code::InvalidArgument),
        (
            "bad hash text",
            vec![
                header(5000, "../../etc", &task.lease_id, &job.id),
                data(&body),
            ],
            Code::InvalidArgument,
        ),
        (
            "unknown job",
            vec![header(5000, &good, &task.lease_id, "ghost"), data(&body)],
            Code::NotFound,
        ),
        (
            "someone else's lease",
            vec![header(5000, &good, "grpc-test-0.0.9", &job.id), data(&body)],
            Code::FailedPrecondition,
        ),
    ];
    for (what, msgs, code) in cases {
        let e = upload(msgs).await.expect_err(what);
        assert_eq!(e.code(), code, "{what}: {e}");
        assert!(!e.message().is_empty());
    }
    // Nothing was committed or left half-written.
    let list = samples
        .list_samples(pb::ListSamplesRequest::default())
        .await
        .expect("list")
        .into_inner();
    assert_eq!(list.total, 0);
    let tmp = c.dir.path().join("data/blobs/tmp");
    let leftovers: Vec<_> = std::fs::read_dir(&tmp)
        .map(|d| d.flatten().collect())
        .unwrap_or_default();
    assert!(leftovers.is_empty(), "temp files left: {leftovers:?}");
    let blob = c.dir.path().join("data/blobs").join(&good[..2]).join(&good);
    assert!(!blob.exists(), "a rejected upload's blob exists");

    // The correct upload commits; repeating it is acknowledged without a second commit.
    let r = upload(vec![
        header(5000, &good, &task.lease_id, &job.id),
        data(&body),
    ])
    .await
    .expect("good upload")
    .into_inner();
    assert!(r.committed);
    let r = upload(vec![
        header(5000, &good, &task.lease_id, &job.id),
        data(&body),
    ])
    .await
    .expect("repeat")
    .into_inner();
    assert!(!r.committed);
    let list = samples
        .list_samples(pb::ListSamplesRequest::default())
        .await
        .expect("list")
        .into_inner();
    assert_eq!(list.total, 1);
    // FetchAsset serves catalog files only.
    let e = workers
        .fetch_asset(pb::FetchAssetRequest {
            blake3: good.clone(),
        })
        .await
        .expect_err("not an asset");
    assert_eq!(e.code(), Code::NotFound);

    let _ = c.stop.take().map(|s| s.send(()));
    c.handle.await.expect("server");
}

/// TLS: a coordinator started with a certificate serves only TLS; a client trusting that
/// certificate works, a plain-text client does not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_serves_clients_that_trust_the_certificate() {
    let mut c = start(|dir, config| {
        let cert = rcgen::generate_simple_self_signed(vec!["localhost".to_string()])
            .expect("self-signed certificate");
        let (cert_path, key_path) = (dir.join("cert.pem"), dir.join("key.pem"));
        std::fs::write(&cert_path, cert.cert.pem()).expect("write cert");
        std::fs::write(&key_path, cert.key_pair.serialize_pem()).expect("write key");
        config.tls = Some((cert_path, key_path));
    })
    .await;
    let (port, cert_path) = (c.port, c.dir.path().join("cert.pem"));

    let (ch, auth) = lightfarm_worker::client::channel(
        &format!("https://localhost:{port}"),
        TOKEN,
        Some(&cert_path),
    )
    .expect("tls channel");
    let mut jobs = pb::jobs_client::JobsClient::with_interceptor(ch, auth);
    let listed = jobs
        .list_jobs(pb::ListJobsRequest {})
        .await
        .expect("TLS call");
    assert!(listed.into_inner().jobs.is_empty());

    let (plain, auth) =
        lightfarm_worker::client::channel(&format!("http://localhost:{port}"), TOKEN, None)
            .expect("channel");
    let mut plain = pb::jobs_client::JobsClient::with_interceptor(plain, auth);
    assert!(
        plain.list_jobs(pb::ListJobsRequest {}).await.is_err(),
        "plain text is refused"
    );

    // The metrics port (and with it the dashboard) is HTTPS with the same certificate.
    let page = https_get(c.metrics_addr.port(), "/login", &cert_path).await;
    assert!(
        page.starts_with("HTTP/1.1 200") && page.contains("name=\"token\""),
        "{page}"
    );
    let mut plain = tokio::net::TcpStream::connect(c.metrics_addr)
        .await
        .expect("connect");
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let _ = plain
        .write_all(b"GET /login HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        .await;
    let mut said = Vec::new();
    let _ = plain.read_to_end(&mut said).await;
    assert!(
        !said.starts_with(b"HTTP/1.1 200"),
        "plain HTTP gets no page: {}",
        String::from_utf8_lossy(&said)
    );

    let _ = c.stop.take().map(|s| s.send(()));
    c.handle.await.expect("server");
}

/// A GET over TLS to localhost:`port`, trusting the PEM certificate at `ca`.
async fn https_get(port: u16, path: &str, ca: &std::path::Path) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    let mut roots = rustls::RootCertStore::empty();
    for cert in rustls::pki_types::CertificateDer::pem_file_iter(ca).expect("pem") {
        roots.add(cert.expect("cert")).expect("root");
    }
    let config = rustls::ClientConfig::builder_with_provider(std::sync::Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .expect("versions")
    .with_root_certificates(roots)
    .with_no_client_auth();
    let tcp = tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .expect("connect");
    let name = rustls::pki_types::ServerName::try_from("localhost").expect("name");
    let mut tls = tokio_rustls::TlsConnector::from(std::sync::Arc::new(config))
        .connect(name, tcp)
        .await
        .expect("TLS handshake with the dashboard");
    tls.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .expect("write");
    let mut buf = Vec::new();
    // A server may close without TLS close_notify; what arrived is the page.
    let _ = tls.read_to_end(&mut buf).await;
    String::from_utf8_lossy(&buf).into_owned()
}
