//! Jobs, tasks, leases and workers: the coordinator's state machine.
//!
//! Everything lives in memory behind one lock (a lease or a commit is a few map operations)
//! and is written through to sled, so a restart rebuilds exactly what was there: jobs, live
//! leases with their deadlines, failures, blocklists. Committed samples are the store's
//! [`SampleIndex`], which is the only authority on "done": a task whose sample is committed
//! is done whatever else the task records say.
//!
//! Semantics (../../shared/DESIGN.md, "Coordinator semantics"):
//! - pull leasing with a deadline; heartbeats extend it; an expired lease requeues the task;
//! - fencing: only the current lease holder completes or fails a task; a commit arriving after
//!   the lease expired is still accepted while no other worker holds the task (the bytes are a
//!   pure function of the sample, so they are the bytes anyone would upload);
//! - a failure requeues the task for a *different* worker; after failures on 3 distinct workers
//!   the task is failed with every reason kept; a worker failing twice in a job is blocklisted
//!   for that job;
//! - locality: a worker gets tasks whose head it already holds first.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::sync::Mutex;

use lightfarm_scene::catalog::Catalog;
use lightfarm_scene::expand::{expand, SampleSpec};
use lightfarm_scene::spec::{DatasetSpec, ResolvedSpec};
use lightfarm_store::SampleIndex;
use serde::{Deserialize, Serialize};

use crate::error::CoordError;

mod leases;
mod workers;

use workers::WorkerRt;
pub use workers::{WorkerHello, WorkerState, WorkerStatus};

/// Distinct workers a task may fail on before it is failed for good.
pub const MAX_FAILED_WORKERS: usize = 3;
/// Failures of one worker within one job after which it gets no more of that job's tasks.
pub const BLOCKLIST_AFTER: u32 = 2;
/// Window of the samples-per-second estimate.
const RATE_WINDOW_S: f64 = 60.0;
/// Failures reported per job in `Job.failures`.
const RECENT_FAILURES: usize = 20;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum RunState {
    Running,
    Paused,
    Cancelled,
}

/// What a job is, as persisted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobRecord {
    pub id: String,
    pub name: String,
    pub priority: i32,
    pub count: u64,
    pub spec_toml: String,
    pub created_unix: f64,
    pub run: RunState,
    /// Submission order: among equal priorities, older jobs lease first.
    pub seq: u64,
    #[serde(default)]
    pub blocklist: BTreeSet<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lease {
    pub id: String,
    pub worker: String,
    pub deadline_unix: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    pub worker: String,
    pub reason: String,
    pub at_unix: f64,
}

/// Persisted per task once anything happened to it (a fresh task has no record).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct TaskRecord {
    attempt: u32,
    lease: Option<Lease>,
    failures: Vec<Failure>,
    failed: bool,
}

/// A task handed to a worker.
#[derive(Clone, Debug)]
pub struct LeasedTask {
    pub job_id: String,
    pub index: u64,
    pub lease_id: String,
    pub deadline_unix: f64,
    pub sample_json: String,
    /// (id, blake3) of every asset the sample reads.
    pub assets: Vec<(String, String)>,
}

/// Counts and rates of one job.
#[derive(Clone, Debug, PartialEq)]
pub struct JobStatus {
    pub record: JobRecord,
    pub queued: u64,
    pub leased: u64,
    pub done: u64,
    pub failed: u64,
    pub samples_per_second: f64,
    pub eta_seconds: f64,
    /// (index, failure), newest last.
    pub recent_failures: Vec<(u64, Failure)>,
}

impl JobStatus {
    pub fn finished(&self) -> bool {
        self.record.run == RunState::Cancelled || self.done + self.failed >= self.record.count
    }
}

/// What an upload may do, decided before its bytes are read.
#[derive(Clone, Debug, PartialEq)]
pub enum UploadCheck {
    /// Go ahead: read, verify and commit.
    Accept { split: String, sample_json: String },
    /// Committed already: acknowledge without storing.
    AlreadyCommitted,
}

struct JobRt {
    rec: JobRecord,
    spec: ResolvedSpec,
    /// Queued indices, and the same indices grouped by head asset (locality).
    queued: BTreeSet<u64>,
    by_head: HashMap<u32, BTreeSet<u64>>,
    /// Head asset (index into `heads`) of every sample.
    head_of: Vec<u32>,
    heads: Vec<String>,
    tasks: HashMap<u64, TaskRecord>,
    leased: u64,
    done: u64,
    failed: u64,
    worker_failures: HashMap<String, u32>,
    commits: VecDeque<f64>,
    recent: VecDeque<(u64, Failure)>,
}

impl JobRt {
    fn dequeue(&mut self, index: u64) {
        if self.queued.remove(&index) {
            if let Some(h) = self.head_of.get(index as usize) {
                if let Some(set) = self.by_head.get_mut(h) {
                    set.remove(&index);
                }
            }
        }
    }

    fn enqueue(&mut self, index: u64) {
        if self.queued.insert(index) {
            if let Some(h) = self.head_of.get(index as usize) {
                self.by_head.entry(*h).or_default().insert(index);
            }
        }
    }

    fn status(&self, now: f64) -> JobStatus {
        let recent: Vec<f64> = self
            .commits
            .iter()
            .copied()
            .filter(|t| now - t <= RATE_WINDOW_S)
            .collect();
        let rate = match (recent.first(), recent.len()) {
            (Some(first), n) if n >= 2 => (n - 1) as f64 / (now - first).max(1e-3),
            _ => 0.0,
        };
        let left = self.rec.count.saturating_sub(self.done + self.failed) as f64;
        JobStatus {
            record: self.rec.clone(),
            queued: self.queued.len() as u64,
            leased: self.leased,
            done: self.done,
            failed: self.failed,
            samples_per_second: rate,
            eta_seconds: if rate > 0.0 { left / rate } else { 0.0 },
            recent_failures: self.recent.iter().cloned().collect(),
        }
    }
}

struct Inner {
    jobs: BTreeMap<String, JobRt>,
    /// lease id → (job, index)
    leases: HashMap<String, (String, u64)>,
    /// (deadline in ms, lease id), for expiry.
    deadlines: BTreeSet<(u64, String)>,
    workers: HashMap<String, WorkerRt>,
    next_seq: u64,
}

/// The coordinator's scheduling state; see the module docs.
pub struct Scheduler {
    inner: Mutex<Inner>,
    jobs_tree: sled::Tree,
    tasks_tree: sled::Tree,
    workers_tree: sled::Tree,
    catalog: Catalog,
    samples: SampleIndex,
    lease_seconds: f64,
    /// Bumped on every change a watcher may care about.
    changed: tokio::sync::watch::Sender<u64>,
}

fn task_key(job: &str, index: u64) -> Vec<u8> {
    let mut k = Vec::with_capacity(job.len() + 9);
    k.extend_from_slice(job.as_bytes());
    k.push(0);
    k.extend_from_slice(&index.to_be_bytes());
    k
}

fn ms(t: f64) -> u64 {
    (t * 1000.0).max(0.0) as u64
}

/// The sample as one-line JSON (what tasks carry and the index stores; `lightfarm spec expand`
/// prints the same content pretty).
fn compact_json(sample: &SampleSpec) -> Result<String, CoordError> {
    serde_json::to_string(sample)
        .map_err(|e| CoordError::BadSpec(format!("sample {}: {e}", sample.index)))
}

fn sled_err(e: sled::Error) -> CoordError {
    CoordError::Storage(e.to_string())
}

fn json_err(e: serde_json::Error) -> CoordError {
    CoordError::Storage(format!("corrupt record: {e}"))
}

impl Scheduler {
    /// Opens the state in `db`, rebuilding jobs, queues and live leases.
    pub fn open(
        db: &sled::Db,
        catalog: Catalog,
        samples: SampleIndex,
        lease_seconds: f64,
    ) -> Result<Scheduler, CoordError> {
        let jobs_tree = db.open_tree("jobs").map_err(sled_err)?;
        let tasks_tree = db.open_tree("tasks").map_err(sled_err)?;
        let workers_tree = db.open_tree("workers").map_err(sled_err)?;
        let (changed, _) = tokio::sync::watch::channel(0);
        let s = Scheduler {
            inner: Mutex::new(Inner {
                jobs: BTreeMap::new(),
                leases: HashMap::new(),
                deadlines: BTreeSet::new(),
                workers: HashMap::new(),
                next_seq: 0,
            }),
            jobs_tree,
            tasks_tree,
            workers_tree,
            catalog,
            samples,
            lease_seconds,
            changed,
        };
        s.recover()?;
        Ok(s)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock leaves state that is still consistent per operation
        // (every mutation is a few map updates); keep serving rather than poisoning forever.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn catalog(&self) -> &Catalog {
        &self.catalog
    }

    pub fn samples(&self) -> &SampleIndex {
        &self.samples
    }

    pub fn lease_seconds(&self) -> f64 {
        self.lease_seconds
    }

    /// A receiver that changes whenever any job's counts or state change.
    pub fn subscribe(&self) -> tokio::sync::watch::Receiver<u64> {
        self.changed.subscribe()
    }

    fn notify(&self) {
        self.changed.send_modify(|v| *v = v.wrapping_add(1));
    }

    fn build_job(&self, rec: JobRecord) -> Result<JobRt, CoordError> {
        let spec = DatasetSpec::from_toml_str(&rec.spec_toml, format!("job {}", rec.id))
            .and_then(|s| s.validate(&self.catalog))
            .map_err(|e| CoordError::BadSpec(e.to_string()))?;
        let mut heads: Vec<String> = Vec::new();
        let mut head_ids: HashMap<String, u32> = HashMap::new();
        let mut head_of = Vec::with_capacity(rec.count as usize);
        for index in 0..rec.count {
            let sample = expand(&spec, index).map_err(|e| CoordError::BadSpec(e.to_string()))?;
            let next = heads.len() as u32;
            let h = *head_ids.entry(sample.head.blake3.clone()).or_insert(next);
            if h == next {
                heads.push(sample.head.blake3);
            }
            head_of.push(h);
        }
        Ok(JobRt {
            rec,
            spec,
            queued: BTreeSet::new(),
            by_head: HashMap::new(),
            head_of,
            heads,
            tasks: HashMap::new(),
            leased: 0,
            done: 0,
            failed: 0,
            worker_failures: HashMap::new(),
            commits: VecDeque::new(),
            recent: VecDeque::new(),
        })
    }

    fn recover(&self) -> Result<(), CoordError> {
        let mut inner = self.lock();
        self.load_workers(&mut inner)?;
        let mut stale: Vec<Vec<u8>> = Vec::new();
        for item in self.jobs_tree.iter() {
            let (_, v) = item.map_err(sled_err)?;
            let rec: JobRecord = serde_json::from_slice(&v).map_err(json_err)?;
            inner.next_seq = inner.next_seq.max(rec.seq + 1);
            let mut job = self.build_job(rec)?;
            let id = job.rec.id.clone();
            for item in self
                .tasks_tree
                .scan_prefix(task_key(&id, 0).split_at(id.len() + 1).0)
            {
                let (k, v) = item.map_err(sled_err)?;
                let Some(ix) = k
                    .get(id.len() + 1..)
                    .and_then(|b| <[u8; 8]>::try_from(b).ok())
                else {
                    continue;
                };
                let task: TaskRecord = serde_json::from_slice(&v).map_err(json_err)?;
                job.tasks.insert(u64::from_be_bytes(ix), task);
            }
            for index in 0..job.rec.count {
                if self
                    .samples
                    .is_committed(&id, index)
                    .map_err(CoordError::from)?
                {
                    job.done += 1;
                    if job.tasks.remove(&index).is_some() {
                        stale.push(task_key(&id, index));
                    }
                    continue;
                }
                match job.tasks.get(&index) {
                    Some(t) if t.failed => job.failed += 1,
                    Some(Task { lease: Some(l), .. }) => {
                        job.leased += 1;
                        inner.leases.insert(l.id.clone(), (id.clone(), index));
                        inner.deadlines.insert((ms(l.deadline_unix), l.id.clone()));
                    }
                    _ => job.enqueue(index),
                }
                if let Some(t) = job.tasks.get(&index) {
                    for f in &t.failures {
                        *job.worker_failures.entry(f.worker.clone()).or_default() += 1;
                    }
                }
            }
            tracing::info!(job = %id, queued = job.queued.len(), leased = job.leased, done = job.done, failed = job.failed, "recovered job");
            inner.jobs.insert(id, job);
        }
        drop(inner);
        let mut batch = sled::Batch::default();
        for key in stale {
            batch.remove(key);
        }
        self.tasks_tree.apply_batch(batch).map_err(sled_err)?;
        Ok(())
    }

    fn persist_job(&self, rec: &JobRecord) -> Result<(), CoordError> {
        let v = serde_json::to_vec(rec).map_err(json_err)?;
        self.jobs_tree
            .insert(rec.id.as_bytes(), v)
            .map_err(sled_err)?;
        Ok(())
    }

    fn persist_task(
        &self,
        job: &str,
        index: u64,
        task: Option<&TaskRecord>,
    ) -> Result<(), CoordError> {
        let key = task_key(job, index);
        match task {
            Some(t) => {
                let v = serde_json::to_vec(t).map_err(json_err)?;
                self.tasks_tree.insert(key, v).map_err(sled_err)?;
            }
            None => {
                self.tasks_tree.remove(key).map_err(sled_err)?;
            }
        }
        Ok(())
    }

    /// Validates `spec_toml` against the catalog and queues its samples.
    pub fn submit(
        &self,
        spec_toml: &str,
        priority: i32,
        now: f64,
    ) -> Result<JobStatus, CoordError> {
        let spec = DatasetSpec::from_toml_str(spec_toml, "submitted spec")
            .and_then(|s| s.validate(&self.catalog))
            .map_err(|e| CoordError::BadSpec(e.to_string()))?;
        let mut inner = self.lock();
        let seq = inner.next_seq;
        inner.next_seq += 1;
        let slug: String = spec
            .name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c.to_ascii_lowercase()
                } else {
                    '-'
                }
            })
            .take(40)
            .collect();
        let rec = JobRecord {
            id: format!("{slug}-{seq}"),
            name: spec.name.clone(),
            priority,
            count: spec.count,
            spec_toml: spec_toml.to_owned(),
            created_unix: now,
            run: RunState::Running,
            seq,
            blocklist: BTreeSet::new(),
        };
        let mut job = self.build_job(rec)?;
        for index in 0..job.rec.count {
            job.enqueue(index);
        }
        self.persist_job(&job.rec)?;
        let status = job.status(now);
        tracing::info!(job = %job.rec.id, count = job.rec.count, priority, "job submitted");
        inner.jobs.insert(job.rec.id.clone(), job);
        drop(inner);
        self.notify();
        Ok(status)
    }

    pub fn job(&self, job_id: &str, now: f64) -> Result<JobStatus, CoordError> {
        let inner = self.lock();
        inner
            .jobs
            .get(job_id)
            .map(|j| j.status(now))
            .ok_or_else(|| CoordError::UnknownJob(job_id.to_owned()))
    }

    pub fn jobs(&self, now: f64) -> Vec<JobStatus> {
        let inner = self.lock();
        let mut v: Vec<JobStatus> = inner.jobs.values().map(|j| j.status(now)).collect();
        v.sort_by_key(|s| s.record.seq);
        v
    }

    /// Pause, resume or cancel.
    pub fn set_run_state(
        &self,
        job_id: &str,
        run: RunState,
        now: f64,
    ) -> Result<JobStatus, CoordError> {
        self.update_record(job_id, now, |rec| {
            if rec.run == RunState::Cancelled && run != RunState::Cancelled {
                return Err(CoordError::Conflict(format!(
                    "job {job_id} was cancelled; submit the spec again to render it"
                )));
            }
            rec.run = run;
            Ok(())
        })
    }

    /// Changes a job's priority (higher leases first), persisted like the rest of the job.
    pub fn set_priority(
        &self,
        job_id: &str,
        priority: i32,
        now: f64,
    ) -> Result<JobStatus, CoordError> {
        self.update_record(job_id, now, |rec| {
            rec.priority = priority;
            Ok(())
        })
    }

    /// Applies `change` to a job's record, persists it and tells the watchers.
    fn update_record(
        &self,
        job_id: &str,
        now: f64,
        change: impl FnOnce(&mut JobRecord) -> Result<(), CoordError>,
    ) -> Result<JobStatus, CoordError> {
        let mut inner = self.lock();
        let job = inner
            .jobs
            .get_mut(job_id)
            .ok_or_else(|| CoordError::UnknownJob(job_id.to_owned()))?;
        change(&mut job.rec)?;
        let rec = job.rec.clone();
        let status = job.status(now);
        drop(inner);
        self.persist_job(&rec)?;
        self.notify();
        Ok(status)
    }

    /// Totals over all jobs, for metrics: (queued, leased, done, failed).
    pub fn totals(&self) -> (u64, u64, u64, u64) {
        let inner = self.lock();
        inner.jobs.values().fold((0, 0, 0, 0), |(q, l, d, f), j| {
            (
                q + j.queued.len() as u64,
                l + j.leased,
                d + j.done,
                f + j.failed,
            )
        })
    }
}

// `recover` matches on a TaskRecord with a lease; the alias keeps that pattern short.
use TaskRecord as Task;
