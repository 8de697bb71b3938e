//! The trainer reading a job from its coordinator (`dataset = "farm://HOST:PORT/JOB"`): it
//! starts on the first committed sample, takes in new ones at checkpoints, rides out a
//! coordinator restart, resumes with the samples its checkpoint recorded, draws exactly the
//! batches of the job's folder export, and refuses a bad address, token, job or crop before
//! its first step.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use lightfarm_integration::{Farm, TOKEN};
use lightfarm_nets::RenderNet;
use lightfarm_scene::Catalog;
use lightfarm_trainer::config::{NetConfig, TrainConfig};
use lightfarm_trainer::farm::{FarmAddress, FarmOptions, FarmSource, StreamState};
use lightfarm_trainer::train::read_losses;
use lightfarm_trainer::StepLog;

const COUNT: u64 = 4;
const SIZE: u32 = 32;

fn spec(name: &str) -> String {
    format!(
        "name = \"{name}\"\nseed = 5\ncount = {COUNT}\nwidth = {SIZE}\nheight = {SIZE}\nspp = 4\n\
         [subject]\nhair_styles = [\"buzz\"]\nheadset_probability = 0.0\n"
    )
}

fn config(dataset: &str, out: &Path, steps: u64, every: u64) -> TrainConfig {
    let mut cfg: TrainConfig = toml::from_str(&format!(
        "dataset = {dataset:?}\nout = {out:?}\nsplit = \"all\"\nsteps = {steps}\nbatch = {COUNT}\nlr = 5e-3\n\
         checkpoint_every = {every}\nkeep_checkpoints = 20\ndevice = \"cpu\"\nloader_threads = 1\n\
         vgg_weights = \"none\"\n\
         [loss]\nadversarial = 0.0\n"
    ))
    .expect("config");
    cfg.net = NetConfig {
        widths: vec![8, 16, 32],
        render_net: RenderNet::Decomposed,
        critic_width: 8,
        adversarial_from: 0,
    };
    cfg.token = Some(TOKEN.into());
    cfg.validate().expect("valid");
    cfg
}

fn train(
    cfg: &TrainConfig,
) -> Result<lightfarm_trainer::train::TrainSummary, lightfarm_trainer::TrainError> {
    lightfarm_trainer::train(
        cfg,
        Catalog::builtin().expect("catalog"),
        &mut (),
        &AtomicBool::new(false),
    )
}

fn stream_state(out: &Path, step: u64) -> StreamState {
    StreamState::load(&out.join("checkpoints").join(format!("step-{step:09}")))
        .expect("stream.json")
        .expect("a streamed run's checkpoint keeps its snapshot")
}

fn assert_one_line_per_step(losses: &[StepLog], steps: u64) {
    let logged: Vec<u64> = losses.iter().map(|l| l.step).collect();
    assert_eq!(
        logged,
        (1..=steps).collect::<Vec<_>>(),
        "each step logged once, in order"
    );
}

fn assert_same_curve(a: &[StepLog], b: &[StepLog], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: step counts");
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x.step, y.step);
        let tol = 1e-5 * x.total.abs().max(1e-3);
        assert!(
            (x.total - y.total).abs() <= tol,
            "{what}, step {}: {} vs {}",
            x.step,
            x.total,
            y.total
        );
    }
}

/// Training starts on the first committed sample while the job renders; the coordinator dies
/// and comes back mid-run; the samples rendered meanwhile join at a checkpoint; the loss of
/// every step is logged exactly once across the restart and a resume.
#[test]
fn a_job_trains_while_it_renders_and_across_a_coordinator_restart() {
    let mut farm = Farm::start();
    let job = farm.submit(&spec("stream-live"));
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let cfg = config(&farm.address(&job.id), &out, 20, 10);
    let trainer = {
        let cfg = cfg.clone();
        std::thread::spawn(move || train(&cfg))
    };
    // The trainer is waiting for a first sample: one worker renders exactly one.
    farm.run_worker("first", 1);
    let started = Instant::now();
    while read_losses(&out).map_or(true, |l| l.is_empty()) {
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "no training step within 300 s of the first sample"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // The coordinator goes away while the trainer trains; a worker waits for it to return.
    farm.stop_coordinator();
    let rest = farm.spawn_worker("rest", COUNT - 1);
    std::thread::sleep(Duration::from_secs(2));
    farm.start_coordinator();
    let summary = trainer
        .join()
        .expect("trainer thread")
        .expect("the run finishes");
    assert_eq!(summary.end_step, 20);
    farm.join(rest);
    farm.wait_done(&job.id, Duration::from_secs(300));

    // Resumed to 40 steps: it starts from step 20's snapshot and takes in the rest at step 30.
    let mut longer = cfg.clone();
    longer.steps = 40;
    let summary = train(&longer).expect("the resumed run finishes");
    assert_eq!((summary.start_step, summary.end_step), (20, 40));
    let losses = read_losses(&out).unwrap();
    assert_one_line_per_step(&losses, 40);
    assert_eq!(
        losses[0].dataset_samples, 1,
        "training started on the first committed sample"
    );
    assert_eq!(
        losses[39].dataset_samples, COUNT,
        "every sample joined by the end"
    );
    let last = stream_state(&out, 40);
    assert_eq!(last.samples.len() as u64, COUNT);
    assert_eq!(last.job, job.id);
    let indices: Vec<u64> = last.samples.iter().map(|s| s.index).collect();
    assert_eq!(indices, (0..COUNT).collect::<Vec<_>>());
    // Each step drew from the snapshot its checkpoint stretch began with.
    for l in &losses {
        let from = (l.step - 1) / 10 * 10;
        if from > 0 {
            assert_eq!(
                l.dataset_samples,
                stream_state(&out, from).samples.len() as u64,
                "step {}",
                l.step
            );
        }
    }
}

/// On a finished job, streaming draws exactly the batches of the job's folder export, a
/// streamed run killed between checkpoints resumes on the same loss curve, and a read of an
/// uncached sample waits out a coordinator outage.
#[test]
fn a_streamed_run_draws_the_batches_of_its_folder_export() {
    let mut farm = Farm::start();
    let job = farm.submit(&spec("stream-done"));
    farm.run_worker("all", COUNT);
    farm.wait_done(&job.id, Duration::from_secs(300));
    let tmp = tempfile::tempdir().unwrap();
    let export = farm.export_folder(&job.id, &tmp.path().join("export"));

    let folder = tmp.path().join("folder");
    train(&config(export.to_str().unwrap(), &folder, 12, 6)).unwrap();
    let streamed = tmp.path().join("streamed");
    train(&config(&farm.address(&job.id), &streamed, 12, 6)).unwrap();
    assert_same_curve(
        &read_losses(&folder).unwrap(),
        &read_losses(&streamed).unwrap(),
        "folder vs stream",
    );

    // A run that died after step 9 with its last checkpoint at step 6 (samples cached on disk
    // and dropped from the cache: both paths serve it).
    let resumed = tmp.path().join("resumed");
    let mut cfg = config(&farm.address(&job.id), &resumed, 9, 6);
    cfg.stream.cache_gb = 1e-9;
    train(&cfg).unwrap();
    let ck = resumed.join("checkpoints");
    std::fs::remove_dir_all(ck.join("step-000000009")).unwrap();
    std::fs::write(ck.join("latest"), "step-000000006").unwrap();
    cfg.steps = 12;
    let summary = train(&cfg).unwrap();
    assert_eq!((summary.start_step, summary.end_step), (6, 12));
    let losses = read_losses(&resumed).unwrap();
    assert_one_line_per_step(&losses, 12);
    assert_same_curve(
        &read_losses(&streamed).unwrap(),
        &losses,
        "straight vs resumed stream",
    );

    // A sample that is not cached while the coordinator is away: the read waits for it.
    let addr = FarmAddress::parse(&farm.address(&job.id)).unwrap();
    let opts = FarmOptions {
        token: TOKEN,
        tls_ca: None,
        cache_dir: tmp.path().join("tiny-cache"),
        cache_bytes: 1,
        split: "all",
        crop: 0,
    };
    let source = FarmSource::open(&addr, &opts, None, &AtomicBool::new(false)).unwrap();
    let started = Instant::now();
    while source.state().samples.len() < COUNT as usize {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the stream never delivered every sample"
        );
        std::thread::sleep(Duration::from_millis(100));
        source.refresh().unwrap();
    }
    let wanted = source
        .state()
        .samples
        .iter()
        .find(|s| !source.cache().contains(s.index))
        .cloned()
        .unwrap();
    farm.stop_coordinator();
    let source = std::sync::Arc::new(source);
    let reader = {
        let source = source.clone();
        std::thread::spawn(move || source.bytes(wanted.index))
    };
    std::thread::sleep(Duration::from_secs(2));
    assert!(
        !reader.is_finished(),
        "the read waits while the coordinator is away"
    );
    farm.start_coordinator();
    let bytes = reader
        .join()
        .unwrap()
        .expect("the read completes once the coordinator is back");
    assert_eq!(blake3::hash(&bytes).to_hex().as_str(), wanted.blake3);
}

/// Every mistake a user can make in a farm dataset is an error naming it, before a step runs.
#[test]
fn bad_addresses_tokens_jobs_and_crops_fail_before_training() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    for (address, needle) in [
        ("farm://127.0.0.1/job-1", "no :PORT"),
        ("farm://127.0.0.1:99999/job-1", "port \"99999\""),
        ("farm://127.0.0.1:7070/", "is not a job id"),
        ("farm://127.0.0.1:7070", "no /JOB"),
    ] {
        let mut cfg = config("/unused", &out, 1, 1);
        cfg.dataset = address.into();
        let err = cfg.validate().expect_err(address);
        assert!(
            err.contains(needle) && err.contains("farm://HOST:PORT/JOB"),
            "{address}: {err}"
        );
    }

    let farm = Farm::start();
    let job = farm.submit(&spec("stream-errors"));
    let mut attempt = 0;
    let mut errors = |mut cfg: TrainConfig| -> String {
        attempt += 1;
        cfg.out = tmp.path().join(format!("attempt-{attempt}"));
        let err = train(&cfg).expect_err("must fail").to_string();
        assert!(
            read_losses(&cfg.out).map_or(true, |l| l.is_empty()),
            "no step ran before: {err}"
        );
        err
    };
    let unknown = errors(config(&farm.address("no-such-job"), &out, 1, 1));
    assert!(
        unknown.contains("\"no-such-job\"") && unknown.contains("lightfarm jobs"),
        "{unknown}"
    );

    let mut cfg = config(&farm.address(&job.id), &out, 1, 1);
    cfg.token = Some("wrong".into());
    let wrong = errors(cfg.clone());
    assert!(
        wrong.contains("refused the token") && wrong.contains("LIGHTFARM_TOKEN"),
        "{wrong}"
    );
    cfg.token = None;
    let missing = errors(cfg.clone());
    assert!(missing.contains("--token"), "{missing}");

    let mut cfg = config(&farm.address(&job.id), &out, 1, 1);
    cfg.crop = 64;
    let crop = errors(cfg);
    assert!(
        crop.contains("crop = 64") && crop.contains(&format!("{SIZE}x{SIZE}")),
        "{crop}"
    );
}
