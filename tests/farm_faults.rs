//! Fault tests with real processes: `kill -9` of a worker mid-render, and separately of the
//! coordinator, during a 50-sample job. The job completes, every sample is committed exactly
//! once, and every sample rendered more than once is bit-identical to the same index rendered
//! undisturbed in this process. The killed worker rejoins under its name; what the workers
//! rendered during the coordinator's outage is replayed from their outboxes.

use std::collections::{HashMap, HashSet};
use std::io::{Read, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use lightfarm_proto::v1 as pb;

const BIN: &str = env!("CARGO_BIN_EXE_lightfarm-under-test");
const TOKEN: &str = "fault-token";
const COUNT: u64 = 50;

fn spec() -> String {
    format!(
        "name = \"faults\"\nseed = 9\ncount = {COUNT}\nwidth = 16\nheight = 16\nspp = 1\n\
         [subject]\nhair_styles = [\"buzz\"]\n"
    )
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// A child process killed (SIGKILL) when dropped, so a failing test leaves nothing running.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn log(dir: &Path, name: &str) -> Stdio {
    Stdio::from(std::fs::File::create(dir.join(format!("{name}.log"))).expect("log file"))
}

/// A coordinator on `port` with leases of `lease_s` seconds, serving /metrics on
/// `metrics_port` if given; its log goes to `<tag>.log`.
fn coordinator(dir: &Path, port: u16, tag: &str, lease_s: u32, metrics_port: Option<u16>) -> Proc {
    let metrics = metrics_port.map_or("off".to_string(), |p| format!("127.0.0.1:{p}"));
    Proc(
        Command::new(BIN)
            .args([
                "serve",
                "coordinator",
                "--listen",
                &format!("127.0.0.1:{port}"),
            ])
            .args(["--metrics-listen", &metrics])
            .args(["--lease-seconds", &lease_s.to_string()])
            .arg("--data")
            .arg(dir.join("data"))
            .env("LIGHTFARM_TOKEN", TOKEN)
            .env("LIGHTFARM_LOG", "info")
            .stderr(log(dir, tag))
            .stdout(Stdio::null())
            .spawn()
            .expect("start coordinator"),
    )
}

/// A worker named `name` with its cache (assets and outbox) in `<dir>/<name>`; its log goes to
/// `<log_tag>.log`, so a restarted worker does not overwrite its predecessor's.
fn worker(dir: &Path, port: u16, name: &str, log_tag: &str) -> Proc {
    Proc(
        Command::new(BIN)
            .args([
                "serve",
                "worker",
                "--coordinator",
                &format!("http://127.0.0.1:{port}"),
            ])
            .args(["--name", name])
            .arg("--cache")
            .arg(dir.join(name))
            .env("LIGHTFARM_TOKEN", TOKEN)
            .env("LIGHTFARM_LOG", "info")
            .stderr(log(dir, log_tag))
            .stdout(Stdio::null())
            .spawn()
            .expect("start worker"),
    )
}

struct Api {
    rt: tokio::runtime::Runtime,
    addr: String,
}

impl Api {
    fn new(port: u16) -> Api {
        Api {
            rt: tokio::runtime::Runtime::new().expect("runtime"),
            addr: format!("http://127.0.0.1:{port}"),
        }
    }

    fn jobs(&self) -> pb::jobs_client::JobsClient<lightfarm_proto::client::AuthedChannel> {
        // A lazy channel needs the runtime's reactor to exist.
        let _in_runtime = self.rt.enter();
        let (ch, auth) =
            lightfarm_proto::client::channel(&self.addr, TOKEN, None).expect("channel");
        pb::jobs_client::JobsClient::with_interceptor(ch, auth)
    }

    /// Submits, retrying while the coordinator starts.
    fn submit(&self) -> String {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let r = self
                .rt
                .block_on(self.jobs().submit_dataset(pb::SubmitDatasetRequest {
                    spec: Some(pb::submit_dataset_request::Spec::Toml(spec())),
                    priority: 0,
                }));
            match r {
                Ok(job) => return job.into_inner().id,
                Err(e) if Instant::now() < deadline => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(200));
                }
                Err(e) => panic!("submit: {e}"),
            }
        }
    }

    /// The job's counts, None while the coordinator is unreachable.
    fn job(&self, id: &str) -> Option<pb::Job> {
        self.rt
            .block_on(self.jobs().get_job(pb::JobRef { job_id: id.into() }))
            .ok()
            .map(|r| r.into_inner())
    }

    fn samples(&self, id: &str) -> Vec<pb::SampleInfo> {
        let _in_runtime = self.rt.enter();
        let (ch, auth) =
            lightfarm_proto::client::channel(&self.addr, TOKEN, None).expect("channel");
        let mut c = pb::samples_client::SamplesClient::with_interceptor(ch, auth);
        self.rt
            .block_on(c.list_samples(pb::ListSamplesRequest {
                job_id: id.into(),
                split: String::new(),
                offset: 0,
                limit: 10_000,
            }))
            .expect("list samples")
            .into_inner()
            .samples
    }

    fn wait_for(
        &self,
        id: &str,
        what: &str,
        timeout: Duration,
        mut pred: impl FnMut(&pb::Job) -> bool,
    ) -> pb::Job {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(job) = self.job(id) {
                if pred(&job) {
                    return job;
                }
            }
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {what}: {:?}",
                self.job(id)
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

fn http_get(port: u16, path: &str) -> std::io::Result<String> {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    )?;
    let mut buf = String::new();
    s.read_to_string(&mut buf)?;
    Ok(buf)
}

/// GET `/metrics` on `port` over plain HTTP/1.1, retried while the server starts.
fn metrics_text(port: u16) -> String {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        match http_get(port, "/metrics") {
            Ok(text) if text.starts_with("HTTP/1.1 200") => return text,
            other if Instant::now() >= deadline => panic!("GET /metrics on {port}: {other:?}"),
            _ => std::thread::sleep(Duration::from_millis(200)),
        }
    }
}

/// A complete outbox entry: its JSON header (written last, by rename) names the sample and
/// lease, and the EXR beside it hashes to what the header says.
#[derive(Debug)]
struct Rendered {
    index: u64,
    lease: String,
    blake3: String,
}

fn outbox_entries(cache: &Path) -> Vec<Rendered> {
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir(cache.join("outbox")) else {
        return out;
    };
    for e in dir.flatten() {
        let p = e.path();
        if p.extension().and_then(|x| x.to_str()) != Some("json") {
            continue;
        }
        let (Ok(json), Ok(exr)) = (std::fs::read(&p), std::fs::read(p.with_extension("exr")))
        else {
            continue;
        };
        let Ok(header) = serde_json::from_slice::<serde_json::Value>(&json) else {
            continue;
        };
        let blake3 = blake3::hash(&exr).to_hex().to_string();
        if header["blake3"].as_str() != Some(blake3.as_str()) {
            continue;
        }
        if let (Some(index), Some(lease)) = (header["index"].as_u64(), header["lease_id"].as_str())
        {
            out.push(Rendered {
                index,
                lease: lease.to_string(),
                blake3,
            });
        }
    }
    out
}

/// Puts every catalog file into a worker's asset cache (`assets/blobs/<blake3>`, what the
/// worker would fetch), so that while the coordinator is down the worker can still finish its
/// current sample instead of waiting for an asset it has not fetched yet.
fn prefill_cache(cache: &Path) {
    let catalog = lightfarm_scene::Catalog::builtin().expect("catalog");
    let blobs = cache.join("assets").join("blobs");
    std::fs::create_dir_all(&blobs).expect("cache dir");
    let file = catalog.root.join(lightfarm_scene::catalog::CATALOG_FILE);
    let hash = blake3::hash(&std::fs::read(&file).expect("catalog file")).to_hex();
    std::fs::copy(&file, blobs.join(hash.as_str())).expect("copy catalog");
    for asset in &catalog.assets {
        std::fs::copy(catalog.path_of(asset), blobs.join(&asset.blake3)).expect("copy asset");
    }
}

fn meta(s: &pb::SampleInfo) -> serde_json::Value {
    serde_json::from_str(&s.metadata_json).expect("metadata")
}

fn done(job: &pb::Job) -> u64 {
    job.counts.as_ref().map(|c| c.done).unwrap_or(0)
}

/// Every index committed once; samples leased more than once (attempt ≥ 2 in the lease id
/// "job.index.attempt") re-rendered here must give the same bytes.
fn check_exactly_once_and_bit_identical(api: &Api, job: &str, dir: &Path) -> usize {
    let samples = api.samples(job);
    let mut idx: Vec<u64> = samples.iter().map(|s| s.index).collect();
    idx.sort();
    assert_eq!(
        idx,
        (0..COUNT).collect::<Vec<_>>(),
        "every sample committed exactly once"
    );

    let catalog = lightfarm_scene::Catalog::builtin().expect("catalog");
    let resolved = lightfarm_scene::spec::DatasetSpec::from_toml_str(&spec(), "faults.toml")
        .and_then(|s| s.validate(&catalog))
        .expect("spec");
    let renderer = lightfarm_render::Renderer::new(&lightfarm_render::vulkan::DeviceRequest::Auto)
        .expect("device");
    let mut rerendered = 0;
    for s in &samples {
        let meta = meta(s);
        let lease = meta["lease"].as_str().unwrap_or_default();
        let attempt: u32 = lease
            .rsplit('.')
            .next()
            .and_then(|a| a.parse().ok())
            .unwrap_or(1);
        if attempt < 2 {
            continue;
        }
        rerendered += 1;
        let sample = lightfarm_scene::expand::expand(&resolved, s.index).expect("expand");
        let json = lightfarm_scene::expand::expand_json(&resolved, s.index).expect("json");
        let path: PathBuf = dir.join(format!("undisturbed-{}.exr", s.index));
        lightfarm_worker::render_to_exr(&renderer, &catalog, &sample, &json, &path)
            .expect("render");
        let bytes = std::fs::read(&path).expect("read");
        assert_eq!(
            blake3::hash(&bytes).to_hex().to_string(),
            s.blake3,
            "sample {} (lease {lease}) differs from an undisturbed render",
            s.index
        );
    }
    rerendered
}

#[test]
fn killing_a_worker_mid_render_loses_nothing() {
    let dir = tempfile::tempdir().expect("tmp");
    let port = free_port();
    let _coord = coordinator(dir.path(), port, "coordinator", 4, None);
    let api = Api::new(port);
    let job = api.submit();
    let mut a = worker(dir.path(), port, "wa", "wa");
    let _b = worker(dir.path(), port, "wb", "wb");
    api.wait_for(&job, "a few commits", Duration::from_secs(300), |j| {
        done(j) >= 4
    });
    // Mid-render: the worker's log says it holds a lease (its last "leased" comes after its
    // last "uploaded"), so a sample is in flight, being rendered or waiting in its outbox.
    let wa_log = dir.path().join("wa.log");
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let text = std::fs::read_to_string(&wa_log).unwrap_or_default();
        let last = text
            .lines()
            .rev()
            .find(|l| l.contains(" leased") || l.contains(" uploaded"));
        if last.is_some_and(|l| l.contains(" leased")) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "worker wa never held a lease:\n{text}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    a.0.kill().expect("kill -9 worker wa");
    let _ = a.0.wait();
    // What is already committed, and what the dead worker left in its outbox (uploaded when
    // it starts again, which shows a restart but not that it works again).
    let last_sequence = api
        .samples(&job)
        .iter()
        .map(|s| s.sequence)
        .max()
        .unwrap_or(0);
    let left_over: HashSet<u64> = outbox_entries(&dir.path().join("wa"))
        .iter()
        .map(|r| r.index)
        .collect();
    let _a = worker(dir.path(), port, "wa", "wa-restarted");
    let end = api.wait_for(&job, "completion", Duration::from_secs(600), |j| {
        j.state != pb::JobState::Running as i32
    });
    assert_eq!(end.state, pb::JobState::Completed as i32, "{end:?}");
    let rerendered = check_exactly_once_and_bit_identical(&api, &job, dir.path());
    // The sample in flight was either re-leased and rendered again, or finished before the
    // kill and uploaded from the outbox by the restarted worker.
    assert!(
        rerendered >= 1 || !left_over.is_empty(),
        "the killed worker's sample was neither re-rendered nor replayed from its outbox"
    );
    let samples = api.samples(&job);
    let rejoined: Vec<u64> = samples
        .iter()
        .filter(|s| s.sequence > last_sequence && !left_over.contains(&s.index))
        .filter(|s| meta(s)["worker"].as_str() == Some("wa"))
        .map(|s| s.index)
        .collect();
    let by_worker: Vec<(u64, u64, String)> = samples
        .iter()
        .map(|s| (s.sequence, s.index, meta(s)["worker"].to_string()))
        .collect();
    assert!(
        !rejoined.is_empty(),
        "the restarted worker wa committed a sample it leased after the restart (committed \
         before: up to sequence {last_sequence}; left in its outbox: {left_over:?}; all \
         (sequence, index, worker): {by_worker:?})"
    );
}

#[test]
fn killing_the_coordinator_mid_job_loses_nothing() {
    let dir = tempfile::tempdir().expect("tmp");
    let port = free_port();
    // Leases outlive the outage, so a result rendered during it is still the current lease's
    // when it is uploaded afterwards and must be committed from the outbox, not re-rendered.
    const LEASE_S: u32 = 60;
    let mut coord = coordinator(dir.path(), port, "coordinator", LEASE_S, None);
    let api = Api::new(port);
    let job = api.submit();
    let caches = [dir.path().join("wa"), dir.path().join("wb")];
    for cache in &caches {
        prefill_cache(cache);
    }
    let _a = worker(dir.path(), port, "wa", "wa");
    let _b = worker(dir.path(), port, "wb", "wb");
    api.wait_for(&job, "some commits", Duration::from_secs(300), |j| {
        done(j) >= 8
    });
    let before: Vec<(u64, String)> = api
        .samples(&job)
        .into_iter()
        .map(|s| (s.index, s.blake3))
        .collect();
    coord.0.kill().expect("kill -9 coordinator");
    let _ = coord.0.wait();
    // Workers finish what they hold into their outboxes while it is down. An entry may also be
    // a sample committed just before the kill whose acknowledgement was lost; those do not
    // show a replay.
    let committed_before: HashSet<u64> = before.iter().map(|(i, _)| *i).collect();
    let deadline = Instant::now() + Duration::from_secs(120);
    let during_outage = loop {
        let fresh: Vec<Rendered> = caches
            .iter()
            .flat_map(|c| outbox_entries(c))
            .filter(|r| !committed_before.contains(&r.index))
            .collect();
        if !fresh.is_empty() {
            break fresh;
        }
        assert!(
            Instant::now() < deadline,
            "no worker wrote a sample to its outbox within 120 s of the coordinator's death \
             (see wa.log, wb.log in {})",
            dir.path().display()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let metrics_port = free_port();
    let _coord2 = coordinator(
        dir.path(),
        port,
        "coordinator-restarted",
        LEASE_S,
        Some(metrics_port),
    );
    let end = api.wait_for(&job, "completion", Duration::from_secs(600), |j| {
        j.state != pb::JobState::Running as i32
    });
    assert_eq!(end.state, pb::JobState::Completed as i32, "{end:?}");
    let after: HashMap<u64, (String, String)> = api
        .samples(&job)
        .into_iter()
        .map(|s| {
            let lease = meta(&s)["lease"].as_str().unwrap_or_default().to_string();
            (s.index, (s.blake3, lease))
        })
        .collect();
    for (index, hash) in before {
        assert_eq!(
            after.get(&index).map(|(h, _)| h),
            Some(&hash),
            "sample {index} committed before the crash is kept as it was"
        );
    }
    for r in &during_outage {
        assert_eq!(
            after.get(&r.index),
            Some(&(r.blake3.clone(), r.lease.clone())),
            "sample {} rendered into an outbox during the outage is committed from it after \
             the restart (same bytes, same lease)",
            r.index
        );
    }
    check_exactly_once_and_bit_identical(&api, &job, dir.path());

    // The restarted coordinator counts what this data directory holds, not what it committed
    // itself since it started.
    let text = metrics_text(metrics_port);
    assert!(
        text.lines()
            .any(|l| l == format!("lightfarm_samples_committed_total {COUNT}")),
        "lightfarm_samples_committed_total {COUNT} missing in:\n{text}"
    );
    assert!(
        text.lines()
            .any(|l| l.starts_with("lightfarm_duplicate_uploads_total ")),
        "lightfarm_duplicate_uploads_total missing in:\n{text}"
    );
}

#[test]
fn sigterm_drains_a_worker() {
    let dir = tempfile::tempdir().expect("tmp");
    let port = free_port();
    let _coord = coordinator(dir.path(), port, "coordinator", 4, None);
    let api = Api::new(port);
    let job = api.submit();
    let mut w = worker(dir.path(), port, "wd", "wd");
    // One worker, two leases: it prepares the next sample while it renders the current one.
    let before = done(&api.wait_for(
        &job,
        "a first commit, then two leases held by the one worker",
        Duration::from_secs(300),
        |j| done(j) >= 1 && j.counts.as_ref().is_some_and(|c| c.leased == 2),
    ));
    let pid = w.0.id().to_string();
    let status = Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill -TERM");
    assert!(status.success());
    let deadline = Instant::now() + Duration::from_secs(120);
    let exit = loop {
        if let Some(s) = w.0.try_wait().expect("wait") {
            break s;
        }
        assert!(Instant::now() < deadline, "worker did not drain and exit");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(exit.success(), "drained worker exits cleanly: {exit:?}");
    // The sample it was rendering and the one it had prepared were finished and uploaded, not
    // left to expire.
    let job_now = api.job(&job).expect("job");
    let counts = job_now.counts.expect("counts");
    assert_eq!(counts.leased, 0, "no lease left behind: {counts:?}");
    assert!(
        counts.done >= before + 2,
        "both samples it held were committed (done {before} while it held two): {counts:?}"
    );
    let log = std::fs::read_to_string(dir.path().join("wd.log")).unwrap_or_default();
    assert!(log.contains("shutdown requested"), "{log}");
}
