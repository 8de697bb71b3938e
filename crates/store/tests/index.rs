use std::sync::{Arc, Barrier};
use std::time::Duration;

use lightfarm_store::{hash_hex, CommitOutcome, SampleIndex, SampleRecord};

fn open_db(dir: &std::path::Path) -> sled::Db {
    sled::Config::new()
        .path(dir.join("db"))
        .open()
        .expect("open sled")
}

fn h(job: &str, index: u64) -> String {
    hash_hex(format!("{job}/{index}").as_bytes())
}

fn commit(idx: &SampleIndex, job: &str, index: u64, split: &str) -> CommitOutcome {
    idx.commit(
        job,
        index,
        split,
        &h(job, index),
        100 + index,
        &format!(r#"{{"i":{index}}}"#),
        1_700_000_000.0 + index as f64,
    )
    .expect("commit")
}

#[test]
fn second_commit_returns_the_first_record() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("index");
    let first = match commit(&idx, "job-a", 3, "train") {
        CommitOutcome::Committed(r) => r,
        other => panic!("expected Committed, got {other:?}"),
    };
    assert_eq!(first.sequence, 1);
    assert_eq!(first.blake3, h("job-a", 3));
    // A re-upload with different content/metadata must not replace the first record.
    let again = idx
        .commit("job-a", 3, "val", &hash_hex(b"other"), 1, "{}", 1.0)
        .expect("commit again");
    assert_eq!(again, CommitOutcome::AlreadyCommitted(first.clone()));
    assert_eq!(idx.get("job-a", 3).expect("get"), Some(first.clone()));
    assert_eq!(idx.count("job-a").expect("count"), 1);
    assert_eq!(idx.latest_sequence(), 1);
    assert_eq!(idx.since(0, None, None, 100).expect("since"), vec![first]);
    // The sequence did not advance: the next sample gets 2.
    assert_eq!(commit(&idx, "job-a", 4, "train").record().sequence, 2);
    assert!(idx.is_committed("job-a", 3).expect("is_committed"));
    assert!(!idx.is_committed("job-a", 5).expect("is_committed"));
    assert_eq!(idx.get("job-a", 5).expect("get"), None);
}

#[test]
fn sequences_increase_across_jobs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("index");
    let mut seqs = Vec::new();
    for (job, i) in [("b", 0), ("a", 9), ("b", 1), ("c", 0), ("a", 2)] {
        seqs.push(commit(&idx, job, i, "train").record().sequence);
    }
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    assert_eq!(idx.count("a").expect("count"), 2);
    assert_eq!(idx.count("b").expect("count"), 2);
    assert_eq!(idx.count("c").expect("count"), 1);
    assert_eq!(idx.count("none").expect("count"), 0);
    // The total over jobs (the coordinator's committed-samples counter starts from it) counts
    // each sample once, re-uploads included, and survives a reopen.
    commit(&idx, "a", 9, "train");
    assert_eq!(idx.total_count().expect("total"), 5);
    drop(idx);
    db.flush().expect("flush");
    drop(db);
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("reopen");
    assert_eq!(idx.total_count().expect("total"), 5);
}

#[test]
fn list_orders_by_index_and_filters() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("index");
    // Commit out of order, with indices whose little-endian or decimal order would differ.
    for i in [300u64, 2, 256, 1, 10, 0, 255] {
        let split = if i % 2 == 0 { "train" } else { "val" };
        commit(&idx, "job", i, split);
    }
    commit(&idx, "jo", 5, "train"); // a prefix of "job" must not leak into its listing
    commit(&idx, "job2", 7, "train");

    let (all, total) = idx.list(Some("job"), None, 0, 100).expect("list");
    assert_eq!(total, 7);
    let indices: Vec<u64> = all.iter().map(|r| r.index).collect();
    assert_eq!(indices, vec![0, 1, 2, 10, 255, 256, 300]);

    let (page, total) = idx.list(Some("job"), None, 2, 3).expect("page");
    assert_eq!(total, 7);
    assert_eq!(
        page.iter().map(|r| r.index).collect::<Vec<_>>(),
        vec![2, 10, 255]
    );

    let (train, total) = idx.list(Some("job"), Some("train"), 1, 2).expect("train");
    assert_eq!(total, 5); // 0, 2, 10, 256, 300
    assert_eq!(
        train.iter().map(|r| r.index).collect::<Vec<_>>(),
        vec![2, 10]
    );
    let (train_all, _) = idx.list(Some("job"), Some("train"), 0, 100).expect("train");
    assert_eq!(
        train_all.iter().map(|r| r.index).collect::<Vec<_>>(),
        vec![0, 2, 10, 256, 300]
    );
    let (val, total) = idx.list(None, Some("val"), 0, 100).expect("val");
    assert_eq!(total, 2); // 1, 255
    assert!(val.iter().all(|r| r.split == "val" && r.job_id == "job"));

    let (_, total) = idx.list(None, None, 0, 0).expect("everything");
    assert_eq!(total, 9);
    let (everything, _) = idx.list(None, None, 0, 100).expect("everything");
    let jobs: Vec<&str> = everything.iter().map(|r| r.job_id.as_str()).collect();
    assert_eq!(
        jobs,
        vec!["jo", "job", "job", "job", "job", "job", "job", "job", "job2"]
    );

    let (beyond, total) = idx.list(Some("job"), None, 50, 10).expect("beyond");
    assert!(beyond.is_empty());
    assert_eq!(total, 7);
    let (none, total) = idx.list(Some("missing"), None, 0, 10).expect("missing");
    assert!(none.is_empty());
    assert_eq!(total, 0);
}

#[test]
fn since_returns_commit_order() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("index");
    let order = [
        ("x", 5u64, "train"),
        ("y", 1, "val"),
        ("x", 0, "val"),
        ("x", 3, "train"),
        ("y", 0, "train"),
    ];
    let mut records: Vec<SampleRecord> = Vec::new();
    for (job, i, split) in order {
        records.push(commit(&idx, job, i, split).into_record());
    }
    assert_eq!(idx.since(0, None, None, 100).expect("since"), records);
    assert_eq!(idx.since(1, None, None, 100).expect("since"), records);
    let from3 = idx
        .since(records[2].sequence, None, None, 2)
        .expect("since");
    assert_eq!(from3, records[2..4].to_vec());
    let x: Vec<(String, u64)> = idx
        .since(0, Some("x"), None, 100)
        .expect("since")
        .into_iter()
        .map(|r| (r.job_id, r.index))
        .collect();
    assert_eq!(x, vec![("x".into(), 5), ("x".into(), 0), ("x".into(), 3)]);
    let x_train: Vec<u64> = idx
        .since(0, Some("x"), Some("train"), 100)
        .expect("since")
        .into_iter()
        .map(|r| r.index)
        .collect();
    assert_eq!(x_train, vec![5, 3]);
    // Resuming past the end yields nothing.
    let last = records.last().expect("records").sequence;
    assert!(idx
        .since(last + 1, None, None, 100)
        .expect("since")
        .is_empty());
    assert!(idx.since(0, None, None, 0).expect("since").is_empty());
}

#[test]
fn survives_close_and_reopen() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (first, second);
    {
        let db = open_db(dir.path());
        let idx = SampleIndex::open(&db).expect("index");
        first = commit(&idx, "job", 0, "train").into_record();
        second = commit(&idx, "job", 1, "val").into_record();
        idx.flush().expect("flush");
    }
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("reopen");
    assert_eq!(idx.get("job", 0).expect("get"), Some(first.clone()));
    assert_eq!(idx.count("job").expect("count"), 2);
    assert_eq!(idx.latest_sequence(), second.sequence);
    assert!(
        matches!(commit(&idx, "job", 1, "val"), CommitOutcome::AlreadyCommitted(r) if r == second)
    );
    // The sequence continues after the reopen instead of restarting.
    let third = commit(&idx, "job", 2, "train").into_record();
    assert_eq!(third.sequence, second.sequence + 1);
    assert_eq!(
        idx.since(0, None, None, 10).expect("since"),
        vec![first, second, third]
    );
}

#[test]
fn shares_the_db_with_other_trees() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    // The coordinator's own trees live beside the index.
    let jobs = db.open_tree("jobs").expect("jobs");
    jobs.insert("job", "spec").expect("insert");
    let idx = SampleIndex::open(&db).expect("index");
    commit(&idx, "job", 0, "train");
    assert_eq!(jobs.len(), 1);
    assert_eq!(idx.count("job").expect("count"), 1);
}

#[test]
fn concurrent_commits_of_one_sample_commit_once() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("index");
    let rounds = 20;
    for round in 0..rounds {
        let barrier = Arc::new(Barrier::new(8));
        let handles: Vec<_> = (0..8)
            .map(|t| {
                let idx = idx.clone();
                let barrier = barrier.clone();
                std::thread::spawn(move || {
                    barrier.wait();
                    idx.commit(
                        "race",
                        round,
                        "train",
                        &hash_hex(format!("{round}/{t}").as_bytes()),
                        t,
                        "{}",
                        t as f64,
                    )
                    .expect("commit")
                })
            })
            .collect();
        let outcomes: Vec<CommitOutcome> = handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect();
        let winners: Vec<&SampleRecord> = outcomes
            .iter()
            .filter_map(|o| match o {
                CommitOutcome::Committed(r) => Some(r),
                CommitOutcome::AlreadyCommitted(_) => None,
            })
            .collect();
        assert_eq!(winners.len(), 1, "round {round}: {outcomes:?}");
        // Every loser saw exactly the winner's record.
        for o in &outcomes {
            assert_eq!(o.record(), winners[0]);
        }
    }
    assert_eq!(idx.count("race").expect("count"), rounds);
    let all = idx.since(0, None, None, 1000).expect("since");
    assert_eq!(all.len() as u64, rounds);
    assert_eq!(idx.latest_sequence(), rounds);
}

#[test]
fn commit_rejects_bad_input() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("index");
    let good = hash_hex(b"x");
    assert!(idx.commit("", 0, "train", &good, 1, "{}", 0.0).is_err());
    assert!(idx.commit("a\0b", 0, "train", &good, 1, "{}", 0.0).is_err());
    assert!(idx
        .commit("a", 0, "train", "not-a-hash", 1, "{}", 0.0)
        .is_err());
    assert!(idx
        .commit("a", 0, "train", &good, 1, "{}", f64::NAN)
        .is_err());
    assert_eq!(idx.count("a").expect("count"), 0);
    assert_eq!(idx.latest_sequence(), 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn subscribe_wakes_an_async_waiter() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = open_db(dir.path());
    let idx = SampleIndex::open(&db).expect("index");
    let mut rx = idx.subscribe();
    assert_eq!(*rx.borrow(), 0);
    let waiter = tokio::spawn(async move {
        rx.changed().await.expect("sender alive");
        let seq = *rx.borrow_and_update();
        seq
    });
    // Give the waiter time to park, so this checks a wake-up and not a ready value.
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert!(!waiter.is_finished(), "woke without a commit");
    let committer = idx.clone();
    let rec =
        tokio::task::spawn_blocking(move || commit(&committer, "job", 0, "train").into_record())
            .await
            .expect("commit task");
    let seq = tokio::time::timeout(Duration::from_secs(5), waiter)
        .await
        .expect("waiter was not woken")
        .expect("waiter task");
    assert_eq!(seq, rec.sequence);

    // A duplicate commit changes nothing and wakes nobody.
    let rx = idx.subscribe();
    commit(&idx, "job", 0, "train");
    assert!(!rx.has_changed().expect("sender alive"));
    commit(&idx, "job", 1, "train");
    assert!(rx.has_changed().expect("sender alive"));
}
