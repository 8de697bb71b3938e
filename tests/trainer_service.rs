//! The trainer service as a real process: `lightfarm serve trainer` killed with SIGKILL mid-job
//! resumes the job from its newest checkpoint, cancels on request, and serves
//! `lightfarm train --trainer` and `lightfarm adapt --trainer` (followed through a SIGKILL of
//! the trainer).

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
