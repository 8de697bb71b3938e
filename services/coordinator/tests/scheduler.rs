//! The coordinator's state machine without the network: leases, expiry, fencing, failures,
//! blocklists, locality, priorities, pause/cancel, and recovery after a restart.

use lightfarm_coordinator::scheduler::{
    RunState, Scheduler, UploadCheck, WorkerHello, WorkerState, BLOCKLIST_AFTER,
};
use lightfarm_scene::Catalog;
use lightfarm_store::SampleIndex;

const SPEC: &str = r#"
name = "unit"
seed = 3
count = 20
width = 16
height = 16
spp = 1
"#;

/// The coordinator's sled settings (no background flusher). A restart in the same process can
/// still find the file lock held for a moment by sled's I/O threads of the dropped instance
/// (a restarted coordinator is a new process, whose lock the dead one no longer holds), so the
/// open is retried for a few seconds before failing.
fn open(dir: &std::path::Path) -> (sled::Db, Scheduler) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    let db = loop {
        match sled::Config::new().path(dir).flush_every_ms(None).open() {
            Ok(db) => break db,
            Err(sled::Error::Io(e))
                if e.to_string().contains("could not acquire lock")
                    && std::time::Instant::now() < deadline =>
            {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            Err(e) => panic!("sled at {}: {e}", dir.display()),
        }
    };
    let catalog = Catalog::builtin().expect("catalog");
    let samples = SampleIndex::open(&db).expect("index");
    let s = Scheduler::open(&db, catalog, samples, 30.0).expect("scheduler");
    (db, s)
}

fn commit(s: &Scheduler, job: &str, index: u64, now: f64) {
    commit_by(s, "uploader", job, index, now);
}

fn commit_by(s: &Scheduler, worker: &str, job: &str, index: u64, now: f64) {
    let fake = format!("{:064x}", index + 1);
    s.samples()
        .commit(job, index, "train", &fake, 1, "{}", now)
        .expect("commit");
    s.mark_done(job, index, worker, now).expect("mark done");
}

fn hello(name: &str) -> WorkerHello {
    WorkerHello {
        name: name.into(),
        device: "llvmpipe (cpu)".into(),
        ..WorkerHello::default()
    }
}

#[test]
fn lease_commit_and_counts() {
    let dir = tempfile::tempdir().expect("tmp");
    let (_db, s) = open(dir.path());
    let job = s.submit(SPEC, 0, 100.0).expect("submit").record.id;
    let tasks = s.lease("w1", 5, None, 100.0).expect("lease");
    assert_eq!(tasks.len(), 5);
    let st = s.job(&job, 100.0).expect("job");
    assert_eq!((st.queued, st.leased, st.done), (15, 5, 0));
    // Each task carries its full sample and the assets it needs, hashes included.
    for t in &tasks {
        let v: serde_json::Value = serde_json::from_str(&t.sample_json).expect("json");
        assert_eq!(v["index"], t.index);
        assert!(t.assets.iter().any(|(id, _)| *id == v["head"]["id"]));
        assert!(t.assets.iter().all(|(_, h)| h.len() == 64));
    }
    for t in &tasks {
        assert!(matches!(
            s.check_upload("w1", &t.lease_id, &job, t.index)
                .expect("check"),
            UploadCheck::Accept { .. }
        ));
        commit(&s, &job, t.index, 101.0);
    }
    // A second upload of a committed sample is acknowledged, not accepted again.
    assert_eq!(
        s.check_upload("w1", &tasks[0].lease_id, &job, tasks[0].index)
            .expect("check"),
        UploadCheck::AlreadyCommitted
    );
    let st = s.job(&job, 101.0).expect("job");
    assert_eq!((st.queued, st.leased, st.done), (15, 0, 5));
}

#[test]
fn expired_leases_requeue_and_are_fenced() {
    let dir = tempfile::tempdir().expect("tmp");
    let (_db, s) = open(dir.path());
    let job = s.submit(SPEC, 0, 0.0).expect("submit").record.id;
    let a = s.lease("w1", 1, None, 0.0).expect("lease").remove(0);
    // Heartbeats keep it; silence past the 30 s lease loses it.
    let (lost, _) = s
        .heartbeat("w1", std::slice::from_ref(&a.lease_id), 20.0)
        .expect("hb");
    assert!(lost.is_empty());
    assert_eq!(
        s.expire(45.0).expect("expire"),
        0,
        "heartbeat extended the lease to 50 s"
    );
    assert_eq!(s.expire(51.0).expect("expire"), 1);
    let (lost, _) = s
        .heartbeat("w1", std::slice::from_ref(&a.lease_id), 52.0)
        .expect("hb");
    assert_eq!(lost, vec![a.lease_id.clone()]);
    // Expired but not re-leased: the late result is still welcome.
    assert!(matches!(
        s.check_upload("w1", &a.lease_id, &job, a.index)
            .expect("check"),
        UploadCheck::Accept { .. }
    ));
    // Re-leased to w2: w1's result is fenced off, w2's accepted.
    let b = s.lease("w2", 1, None, 53.0).expect("lease").remove(0);
    assert_eq!(b.index, a.index, "requeued task goes first (lowest index)");
    assert_ne!(b.lease_id, a.lease_id);
    let err = s
        .check_upload("w1", &a.lease_id, &job, a.index)
        .expect_err("fenced");
    assert!(err.to_string().contains("no longer current"), "{err}");
    assert!(matches!(
        s.check_upload("w2", &b.lease_id, &job, b.index)
            .expect("check"),
        UploadCheck::Accept { .. }
    ));
    // Unknown job and out-of-range index are errors naming them.
    assert!(s
        .check_upload("w2", &b.lease_id, "nope", 0)
        .expect_err("unknown")
        .to_string()
        .contains("nope"));
    assert!(s.check_upload("w2", &b.lease_id, &job, 999).is_err());
}

#[test]
fn failures_retry_elsewhere_then_fail_with_all_reasons() {
    let dir = tempfile::tempdir().expect("tmp");
    let (_db, s) = open(dir.path());
    let job = s
        .submit(&SPEC.replace("count = 20", "count = 1"), 0, 0.0)
        .expect("submit")
        .record
        .id;
    for (i, w) in ["w1", "w2", "w3"].iter().enumerate() {
        let t = s.lease(w, 1, None, i as f64).expect("lease");
        assert_eq!(t.len(), 1, "{w} gets the task");
        // The worker that failed it never gets it again.
        assert!(s.lease(w, 1, None, i as f64).expect("lease").is_empty());
        let retry = s
            .fail(w, &t[0].lease_id, &format!("boom on {w}"), i as f64)
            .expect("fail");
        assert_eq!(retry, i < 2, "retried until 3 distinct workers failed it");
        assert!(
            s.lease(w, 1, None, i as f64).expect("lease").is_empty(),
            "{w} never gets it back"
        );
    }
    let st = s.job(&job, 3.0).expect("job");
    assert_eq!((st.queued, st.failed, st.done), (0, 1, 0));
    assert!(st.finished());
    let reasons: Vec<&str> = st
        .recent_failures
        .iter()
        .map(|(_, f)| f.reason.as_str())
        .collect();
    assert_eq!(reasons, ["boom on w1", "boom on w2", "boom on w3"]);
    // Failing with a lease one does not hold is refused.
    assert!(s.fail("w9", "unit-0.0.1", "x", 4.0).is_err());
}

#[test]
fn repeated_failures_blocklist_a_worker_for_the_job() {
    let dir = tempfile::tempdir().expect("tmp");
    let (_db, s) = open(dir.path());
    let job = s.submit(SPEC, 0, 0.0).expect("submit").record.id;
    for _ in 0..BLOCKLIST_AFTER {
        let t = s.lease("bad", 1, None, 0.0).expect("lease").remove(0);
        s.fail("bad", &t.lease_id, "driver crash", 0.0)
            .expect("fail");
    }
    assert!(
        s.lease("bad", 4, None, 1.0).expect("lease").is_empty(),
        "blocklisted"
    );
    assert_eq!(s.lease("good", 4, None, 1.0).expect("lease").len(), 4);
    assert!(s
        .job(&job, 1.0)
        .expect("job")
        .record
        .blocklist
        .contains("bad"));
}

#[test]
fn locality_priority_pause_and_cancel() {
    let dir = tempfile::tempdir().expect("tmp");
    let (_db, s) = open(dir.path());
    let low = s.submit(SPEC, 0, 0.0).expect("submit").record.id;
    // Locality: a worker holding one head's file gets that head's samples first.
    let all = s.lease("probe", 20, None, 0.0).expect("lease");
    let head_of = |t: &lightfarm_coordinator::scheduler::LeasedTask| {
        let v: serde_json::Value = serde_json::from_str(&t.sample_json).expect("json");
        v["head"]["blake3"].as_str().unwrap_or_default().to_string()
    };
    let wanted = head_of(&all[all.len() - 1]);
    let expected: Vec<u64> = all
        .iter()
        .filter(|t| head_of(t) == wanted)
        .map(|t| t.index)
        .collect();
    for t in &all {
        s.fail("probe", &t.lease_id, "probe", 0.0).expect("release");
    }
    let got = s
        .lease(
            "local",
            expected.len() as u32,
            Some(vec![wanted.clone()]),
            1.0,
        )
        .expect("lease");
    assert_eq!(
        got.iter().map(|t| t.index).collect::<Vec<_>>(),
        expected,
        "same-head samples first"
    );

    // Priority: a higher-priority job leases before an older one.
    let high = s.submit(SPEC, 10, 2.0).expect("submit").record.id;
    let t = s.lease("w", 1, None, 2.0).expect("lease");
    assert_eq!(t[0].job_id, high);
    // Paused: no leases from it; resumed: again.
    s.set_run_state(&high, RunState::Paused, 3.0)
        .expect("pause");
    assert_eq!(s.lease("w", 1, None, 3.0).expect("lease")[0].job_id, low);
    s.set_run_state(&high, RunState::Running, 4.0)
        .expect("resume");
    assert_eq!(s.lease("w", 1, None, 4.0).expect("lease")[0].job_id, high);
    // Cancelled: no leases, heartbeats lose the leases, uploads refused, cannot resume.
    s.set_run_state(&high, RunState::Cancelled, 5.0)
        .expect("cancel");
    assert!(s
        .lease("w", 50, None, 5.0)
        .expect("lease")
        .iter()
        .all(|t| t.job_id == low));
    let (lost, _) = s
        .heartbeat("w", std::slice::from_ref(&t[0].lease_id), 5.0)
        .expect("hb");
    assert_eq!(lost.len(), 1);
    assert!(s
        .check_upload("w", &t[0].lease_id, &high, t[0].index)
        .is_err());
    assert!(s.set_run_state(&high, RunState::Running, 6.0).is_err());
    assert!(s.job(&high, 6.0).expect("job").finished());
}

#[test]
fn a_restart_keeps_jobs_live_leases_and_commits() {
    let dir = tempfile::tempdir().expect("tmp");
    let (job, leased, committed) = {
        let (db, s) = open(dir.path());
        let job = s.submit(SPEC, 0, 0.0).expect("submit").record.id;
        let t = s.lease("w1", 3, None, 0.0).expect("lease");
        commit(&s, &job, t[0].index, 1.0);
        let bad = s.lease("w2", 1, None, 1.0).expect("lease").remove(0);
        s.fail("w2", &bad.lease_id, "x", 1.0).expect("fail");
        db.flush().expect("flush");
        (job, t[1..].to_vec(), t[0].index)
    };
    let (_db, s) = open(dir.path());
    let st = s.job(&job, 2.0).expect("job after restart");
    assert_eq!((st.done, st.leased, st.queued), (1, 2, 17));
    // The live leases are honoured: their holder can still upload, and they expire on time.
    for t in &leased {
        assert!(matches!(
            s.check_upload("w1", &t.lease_id, &job, t.index)
                .expect("check"),
            UploadCheck::Accept { .. }
        ));
    }
    assert_eq!(
        s.check_upload("w1", "x", &job, committed).expect("check"),
        UploadCheck::AlreadyCommitted
    );
    assert_eq!(s.expire(29.0).expect("expire"), 0);
    assert_eq!(s.expire(31.0).expect("expire"), 2);
    // The failure record survived: w2 does not get that task again.
    let again: Vec<u64> = s
        .lease("w2", 20, None, 32.0)
        .expect("lease")
        .iter()
        .map(|t| t.index)
        .collect();
    assert_eq!(again.len(), 18);
}

#[test]
fn a_restarted_worker_gets_its_abandoned_leases_requeued_at_once() {
    let dir = tempfile::tempdir().expect("tmp");
    let (_db, s) = open(dir.path());
    let job = s.submit(SPEC, 0, 0.0).expect("submit").record.id;
    s.register_worker(hello("w5"), 0.0).expect("register");
    s.lease("w5", 2, None, 0.0).expect("lease");
    s.lease("w6", 1, None, 0.0).expect("lease");
    assert_eq!(s.job(&job, 0.0).expect("job").leased, 3);
    // w5 was killed and comes back under its name: no waiting for its deadlines.
    s.register_worker(hello("w5"), 1.0).expect("re-register");
    let st = s.job(&job, 1.0).expect("job");
    assert_eq!((st.leased, st.queued), (1, 19), "only w6's lease is left");
    assert!(s.register_worker(hello(""), 1.0).is_err());
}

#[test]
fn workers_show_what_they_do_and_keep_their_counts_across_a_restart() {
    let dir = tempfile::tempdir().expect("tmp");
    let state = |s: &Scheduler, name: &str, now: f64| {
        s.workers(now)
            .into_iter()
            .find(|w| w.name == name)
            .unwrap_or_else(|| panic!("worker {name} is listed"))
    };
    let job = {
        let (_db, s) = open(dir.path());
        let job = s.submit(SPEC, 0, 0.0).expect("submit").record.id;
        s.register_worker(hello("gpu-a"), 0.0).expect("register");
        assert_eq!(state(&s, "gpu-a", 0.0).state, WorkerState::Idle);
        assert_eq!(state(&s, "gpu-a", 0.0).device, "llvmpipe (cpu)");
        let t = s.lease("gpu-a", 1, None, 1.0).expect("lease");
        let w = state(&s, "gpu-a", 1.0);
        assert_eq!(w.state, WorkerState::Rendering);
        assert_eq!(w.rendering, vec![(job.clone(), t[0].index)]);
        commit_by(&s, "gpu-a", &job, t[0].index, 2.0);
        let t = s.lease("gpu-a", 1, None, 3.0).expect("lease");
        s.fail("gpu-a", &t[0].lease_id, "driver lost", 3.0)
            .expect("fail");
        let w = state(&s, "gpu-a", 3.0);
        assert_eq!((w.state, w.rendered, w.failures), (WorkerState::Idle, 1, 1));
        // Silent for longer than a lease (30 s here): lost.
        assert_eq!(state(&s, "gpu-a", 40.0).state, WorkerState::Lost);
        // A shutdown while rendering: draining, then stopped once it holds nothing.
        let t = s.lease("gpu-a", 1, None, 41.0).expect("lease");
        s.worker_draining("gpu-a", 42.0);
        assert_eq!(state(&s, "gpu-a", 42.0).state, WorkerState::Draining);
        commit_by(&s, "gpu-a", &job, t[0].index, 43.0);
        assert_eq!(state(&s, "gpu-a", 43.0).state, WorkerState::Stopped);
        assert_eq!(state(&s, "gpu-a", 400.0).state, WorkerState::Stopped);
        job
    };
    let (_db, s) = open(dir.path());
    let w = state(&s, "gpu-a", 500.0);
    assert_eq!(
        (w.state, w.rendered, w.failures, w.last_seen_unix),
        (WorkerState::Lost, 2, 1, None),
        "counts and device persist; not heard from since the restart"
    );
    assert_eq!(w.device, "llvmpipe (cpu)");
    s.lease("gpu-a", 1, None, 501.0).expect("lease");
    let w = state(&s, "gpu-a", 501.0);
    assert_eq!(w.state, WorkerState::Rendering);
    assert_eq!(w.rendering[0].0, job);
    assert!(w.blocklisted_in.is_empty());
}
