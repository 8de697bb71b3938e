//! The trainer service as a real process: `lightfarm serve trainer` killed with SIGKILL mid-job
//! resumes the job from its newest checkpoint, cancels on request, and serves
//! `lightfarm train --trainer` and `lightfarm adapt --trainer` (followed through a SIGKILL of
//! the trainer); and the coordinator's dashboard shows a trainer's jobs, curves and relights.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lightfarm-under-test"));
    c.env("LIGHTFARM_TRAIN_DEVICE", "cpu");
    c
}

/// Four 16² samples rendered and exported by `lightfarm demo` (training skipped).
fn dataset() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("demo");
        let r = bin()
            .args(["demo", "--out"])
            .arg(&out)
            .args([
                "--count",
                "4",
                "--size",
                "16",
                "--spp",
                "1",
                "--train-steps",
                "0",
            ])
            .output()
            .expect("run lightfarm demo");
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        (tmp, out.join("dataset"))
    })
    .1
}

fn losses(run: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(run.join("losses.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// `lightfarm serve trainer` killed with SIGKILL mid-job: restarted on the same data directory,
/// it resumes the job from its newest checkpoint and the loss log stays one line per step.
#[test]
fn the_trainer_service_resumes_a_job_after_sigkill() {
    use lightfarm_proto::v1 as pb;
    let tmp = tempfile::tempdir().expect("tmp");
    let data = tmp.path().join("trainer");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .expect("port")
        .local_addr()
        .expect("addr")
        .port();
    let listen = format!("127.0.0.1:{port}");
    let start = || {
        bin()
            .args([
                "serve",
                "trainer",
                "--data",
                data.to_str().expect("utf8"),
                "--listen",
                &listen,
                "--token",
                "t0k",
            ])
            .arg("--datasets")
            .arg(dataset().parent().expect("parent"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn trainer")
    };
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let connect = || {
        rt.block_on(async {
            let started = Instant::now();
            loop {
                let ep = tonic::transport::Endpoint::from_shared(format!("http://{listen}"))
                    .expect("endpoint");
                if let Ok(ch) = ep.connect().await {
                    let auth = |mut r: tonic::Request<()>| {
                        r.metadata_mut()
                            .insert("authorization", "Bearer t0k".parse().expect("header"));
                        Ok(r)
                    };
                    return pb::trainer_client::TrainerClient::with_interceptor(ch, auth);
                }
                assert!(
                    started.elapsed() < Duration::from_secs(30),
                    "trainer did not come up"
                );
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        })
    };
    let step_of = |c: &mut pb::trainer_client::TrainerClient<_>, id: &str| -> (u64, i32) {
        let jobs = rt
            .block_on(c.list_train_jobs(pb::ListTrainJobsRequest {}))
            .expect("list")
            .into_inner()
            .jobs;
        let j = jobs.into_iter().find(|j| j.id == id).expect("job listed");
        (j.step, j.state)
    };
    let wait_step = |c: &mut pb::trainer_client::TrainerClient<_>, id: &str, min: u64| {
        let started = Instant::now();
        while step_of(c, id).0 < min {
            assert!(
                started.elapsed() < Duration::from_secs(300),
                "job stuck below step {min}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    };

    let mut server = start();
    let mut c = connect();
    let job = rt
        .block_on(c.submit_train_job(pb::SubmitTrainJobRequest {
            config_toml: "crop = 16\ncheckpoint_every = 3\nloader_threads = 1\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n".into(),
            dataset: "dataset".into(),
            split: "all".into(),
            steps: 100_000,
            batch: 2,
        }))
        .expect("submit")
        .into_inner();
    wait_step(&mut c, &job.id, 7);
    server.kill().expect("SIGKILL");
    let _ = server.wait();

    let mut server = start();
    let mut c = connect();
    wait_step(&mut c, &job.id, 12);
    let cancelled = rt
        .block_on(c.cancel_train_job(pb::TrainJobRef {
            job_id: job.id.clone(),
        }))
        .expect("cancel")
        .into_inner();
    assert_eq!(cancelled.id, job.id);
    let started = Instant::now();
    while step_of(&mut c, &job.id).1 != pb::TrainJobState::Cancelled as i32 {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "cancel did not take"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // `lightfarm train --trainer` submits a config (its `dataset` names an export under the
    // trainer's --datasets) and follows the job to its end.
    let cfg = tmp.path().join("remote.toml");
    std::fs::write(
        &cfg,
        "dataset = \"dataset\"\nout = \"ignored\"\nsplit = \"all\"\nbatch = 2\ncrop = 16\nloader_threads = 1\n\
         [net]\nwidths = [8, 16, 32]\ncritic_width = 8\n",
    )
    .expect("config");
    let r = bin()
        .args([
            "train",
            cfg.to_str().expect("utf8"),
            "--steps",
            "4",
            "--trainer",
            &format!("http://{listen}"),
            "--token",
            "t0k",
        ])
        .output()
        .expect("remote train");
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(
        String::from_utf8_lossy(&r.stdout).contains("completed at step 4"),
        "{}",
        String::from_utf8_lossy(&r.stdout)
    );

    // `lightfarm adapt --trainer` adapts that job's final model on a photo folder under the
    // trainer's --datasets; the trainer is killed mid-adaptation and the command follows the
    // resumed job to its end.
    let root = dataset().parent().expect("parent");
    std::fs::create_dir_all(root.join("portraits")).expect("mkdir");
    let photo = lightfarm_scene::catalog::builtin_assets_dir().join("photos/astronaut.png");
    std::fs::copy(&photo, root.join("portraits/astronaut.png"))
        .unwrap_or_else(|e| panic!("{}: {e}; run ./scripts/fetch-models.sh", photo.display()));
    let adapt_cfg = tmp.path().join("adapt.toml");
    std::fs::write(
        &adapt_cfg,
        "base = \"ignored\"\nphotos = \"ignored\"\nout = \"ignored\"\nbatch = 1\nsize = 32\n\
         checkpoint_every = 2\nhdris = [\"studio_small_03\", \"venice_sunset\"]\ncritic_width = 8\n\
         olat_lights = 8\nvgg_weights = \"none\"\n[weights]\nsimilarity = 0\nidentity = 0\n\
         [adapter]\nbase = 4\nblocks = 2\n",
    )
    .expect("adapt config");
    let remote = bin()
        .args(["adapt", adapt_cfg.to_str().expect("utf8"), "--steps", "12"])
        .args(["--trainer", &format!("http://{listen}"), "--token", "t0k"])
        .args(["--base-job", "train-000002", "--photos", "portraits"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("remote adapt");
    let adapt_id = "adapt-000003";
    let started = Instant::now();
    while rt
        .block_on(c.list_train_jobs(pb::ListTrainJobsRequest {}))
        .expect("list")
        .into_inner()
        .jobs
        .iter()
        .all(|j| j.id != adapt_id)
    {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no adaptation job"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    wait_step(&mut c, adapt_id, 3);
    let (at_kill, _) = step_of(&mut c, adapt_id);
    server.kill().expect("SIGKILL");
    let _ = server.wait();
    let mut server = start();
    let r = remote.wait_with_output().expect("remote adapt");
    let said = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(
        said.contains(adapt_id) && said.contains("completed at step 12"),
        "{said}"
    );
    let adapt_steps: Vec<u64> = losses(&data.join("jobs").join(adapt_id).join("run"))
        .iter()
        .map(|l| l["step"].as_u64().expect("step"))
        .collect();
    assert_eq!(
        adapt_steps,
        (1..=12).collect::<Vec<_>>(),
        "one line per step across the kill"
    );
    assert!(
        at_kill < 12,
        "the kill came after the adaptation ended (step {at_kill})"
    );

    server.kill().expect("kill");
    let _ = server.wait();
    let steps: Vec<u64> = losses(&data.join("jobs").join(&job.id).join("run"))
        .iter()
        .map(|l| l["step"].as_u64().expect("step"))
        .collect();
    assert!(steps.len() >= 12, "{steps:?}");
    assert_eq!(
        steps,
        (1..=steps.len() as u64).collect::<Vec<_>>(),
        "one line per step across the kill"
    );
}

/// One HTTP/1.1 exchange with the dashboard; the status, the headers' text and the body bytes.
fn http(addr: &str, req: &str) -> (u16, String, Vec<u8>) {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).expect("connect to the dashboard");
    s.set_read_timeout(Some(Duration::from_secs(300)))
        .expect("timeout");
    s.write_all(req.as_bytes()).expect("write");
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).expect("read");
    let at = buf
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a response");
    let head = String::from_utf8_lossy(&buf[..at]).into_owned();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .expect("status");
    (status, head, buf[at + 4..].to_vec())
}

fn get(addr: &str, path: &str, cookie: &str) -> (u16, String, Vec<u8>) {
    http(
        addr,
        &format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\nCookie: {cookie}\r\n\r\n"),
    )
}

/// `lightfarm serve coordinator --trainer URL`: the dashboard's trainer pages show a train job
/// on the farm's own samples (`farm://`), its loss curves as SVG, and a committed sample
/// relit by the job's newest checkpoint (a PNG of the sample's size).
#[test]
fn the_dashboard_shows_the_trainer_jobs_curves_and_relit_samples() {
    use lightfarm_proto::v1 as pb;
    let tmp = tempfile::tempdir().expect("tmp");
    let port = || {
        std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("port")
    };
    let (grpc, web, trainer) = (port(), port(), port());
    let spawn = |args: &[&str]| {
        bin()
            .args(args)
            .args(["--token", "t0k"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn lightfarm")
    };
    let data = |d: &str| tmp.path().join(d).to_str().expect("utf8").to_owned();
    let mut coordinator = spawn(&[
        "serve",
        "coordinator",
        "--data",
        &data("coordinator"),
        "--listen",
        &format!("127.0.0.1:{grpc}"),
        "--metrics-listen",
        &format!("127.0.0.1:{web}"),
        "--trainer",
        &format!("http://127.0.0.1:{trainer}"),
    ]);
    let mut trainer_proc = spawn(&[
        "serve",
        "trainer",
        "--data",
        &data("trainer"),
        "--listen",
        &format!("127.0.0.1:{trainer}"),
        "--datasets",
        &data("."),
        "--coordinator-token",
        "t0k",
    ]);
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let channel = |port: u16| {
        let _in = rt.enter();
        lightfarm_proto::client::channel(&format!("http://127.0.0.1:{port}"), "t0k", None)
            .expect("channel")
    };
    let retry = |what: &str, f: &mut dyn FnMut() -> bool| {
        let started = Instant::now();
        while !f() {
            assert!(
                started.elapsed() < Duration::from_secs(600),
                "waited 10 min for {what}"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    };
    let (ch, auth) = channel(grpc);
    let mut jobs = pb::jobs_client::JobsClient::with_interceptor(ch, auth);
    let mut job = None;
    retry("the coordinator", &mut || {
        job = rt
            .block_on(
                jobs.submit_dataset(pb::SubmitDatasetRequest {
                    spec: Some(pb::submit_dataset_request::Spec::Toml(
                        "name = \"relit\"\nseed = 5\ncount = 2\nwidth = 16\nheight = 16\nspp = 1\n"
                            .into(),
                    )),
                    priority: 0,
                }),
            )
            .ok()
            .map(|j| j.into_inner().id);
        job.is_some()
    });
    let job = job.expect("submitted");
    let worker = bin()
        .args(["serve", "worker", "--coordinator"])
        .arg(format!("http://127.0.0.1:{grpc}"))
        .args([
            "--token",
            "t0k",
            "--name",
            "w",
            "--max-samples",
            "2",
            "--cache",
        ])
        .arg(data("worker"))
        .output()
        .expect("worker");
    assert!(
        worker.status.success(),
        "{}",
        String::from_utf8_lossy(&worker.stderr)
    );

    let (ch, auth) = channel(trainer);
    let mut tc = pb::trainer_client::TrainerClient::with_interceptor(ch, auth);
    let mut train = None;
    retry("the trainer", &mut || {
        let submitted = rt.block_on(tc.submit_train_job(pb::SubmitTrainJobRequest {
                config_toml: "crop = 16\ncheckpoint_every = 1\nloader_threads = 1\n\
                              vgg_weights = \"none\"\n[net]\nwidths = [8, 16, 32]\ncritic_width = 8\n"
                    .into(),
                dataset: format!("farm://127.0.0.1:{grpc}/{job}"),
                split: "all".into(),
                steps: 2,
                batch: 1,
            }));
        match submitted {
            Ok(j) => train = Some(j.into_inner().id),
            Err(s) if lightfarm_proto::client::transient(&s) => {}
            Err(s) => panic!("submitting the train job: {s}"),
        }
        train.is_some()
    });
    let train = train.expect("train job");
    retry("the train job to complete", &mut || {
        let listed = rt
            .block_on(tc.list_train_jobs(pb::ListTrainJobsRequest {}))
            .expect("list")
            .into_inner()
            .jobs;
        let j = listed.iter().find(|j| j.id == train).expect("listed");
        assert_ne!(j.state, pb::TrainJobState::Failed as i32, "{}", j.error);
        j.state == pb::TrainJobState::Completed as i32
    });

    let addr = format!("127.0.0.1:{web}");
    let (status, head, _) = http(
        &addr,
        "POST /login HTTP/1.1\r\nHost: x\r\nConnection: close\r\nContent-Type: \
         application/x-www-form-urlencoded\r\nContent-Length: 9\r\n\r\ntoken=t0k",
    );
    assert_eq!(status, 303, "{head}");
    let cookie = head
        .lines()
        .find_map(|l| l.strip_prefix("set-cookie: "))
        .and_then(|c| c.split(';').next())
        .expect("a session cookie")
        .to_owned();
    let (status, _, body) = get(&addr, "/trainer", &cookie);
    let page = String::from_utf8_lossy(&body);
    assert_eq!(status, 200);
    assert!(
        page.contains(&format!("/trainer/{train}")) && page.contains(">completed<"),
        "{page}"
    );
    let (status, _, body) = get(&addr, &format!("/trainer/{train}"), &cookie);
    let page = String::from_utf8_lossy(&body);
    assert_eq!(status, 200);
    assert!(
        page.contains("<svg") && page.contains("data-term=\"total\""),
        "{page}"
    );
    let relit = format!("/trainer/{train}/relit/{job}/0");
    assert!(page.contains(&relit), "{page}");
    let (status, head, png) = get(&addr, &relit, &cookie);
    assert_eq!(status, 200, "{head} {}", String::from_utf8_lossy(&png));
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "{head}");
    let size = |at: usize| u32::from_be_bytes([png[at], png[at + 1], png[at + 2], png[at + 3]]);
    assert_eq!((size(16), size(20)), (16, 16), "the sample's size");
    // The trainer gone: the page says so instead of failing.
    trainer_proc.kill().expect("kill trainer");
    let _ = trainer_proc.wait();
    let (status, _, body) = get(&addr, "/trainer/table", &cookie);
    assert_eq!(status, 200);
    assert!(
        String::from_utf8_lossy(&body).contains("did not answer"),
        "{}",
        String::from_utf8_lossy(&body)
    );
    coordinator.kill().expect("kill coordinator");
    let _ = coordinator.wait();
}
