//! The workers the coordinator has heard from: what each said when it registered (device,
//! memory), when it last called, what it renders now, how many samples it rendered and failed,
//! which assets it holds. Registration and counters survive a coordinator restart (sled tree
//! `workers`); the rest is live and comes back as the workers call in again.

use std::collections::HashSet;

use lightfarm_scene::catalog::AssetKind;
use serde::{Deserialize, Serialize};

use super::{json_err, sled_err, Inner, Scheduler};
use crate::error::CoordError;

/// A worker as persisted.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub(super) struct WorkerRecord {
    pub device: String,
    pub memory_bytes: u64,
    pub registered_unix: f64,
    pub rendered: u64,
    pub failures: u64,
}

#[derive(Default)]
pub(super) struct WorkerRt {
    pub rec: WorkerRecord,
    pub cached: HashSet<String>,
    /// None until the worker calls after a coordinator restart.
    pub last_seen_unix: Option<f64>,
    /// Said it is shutting down (finishing its sample, then leaving).
    pub draining: bool,
}

/// What a worker says when it registers.
#[derive(Clone, Debug, Default)]
pub struct WorkerHello {
    /// Stable across the worker's restarts (its host name by default).
    pub name: String,
    /// Render device, e.g. "NVIDIA H100 (gpu)".
    pub device: String,
    pub memory_bytes: u64,
    /// BLAKE3 of every asset in its cache.
    pub cached: Vec<String>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorkerState {
    /// Calling in, holding no task.
    Idle,
    /// Holding at least one lease.
    Rendering,
    /// Shutting down: finishing what it holds.
    Draining,
    /// Drained and gone.
    Stopped,
    /// Silent for longer than a lease (or not heard from since the coordinator started).
    Lost,
}

impl WorkerState {
    pub fn as_str(self) -> &'static str {
        match self {
            WorkerState::Idle => "idle",
            WorkerState::Rendering => "rendering",
            WorkerState::Draining => "draining",
            WorkerState::Stopped => "stopped",
            WorkerState::Lost => "lost",
        }
    }
}

/// One worker as the dashboard shows it.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkerStatus {
    pub name: String,
    pub device: String,
    pub memory_bytes: u64,
    pub state: WorkerState,
    pub last_seen_unix: Option<f64>,
    pub rendered: u64,
    pub failures: u64,
    pub cached_assets: usize,
    /// Catalog ids of the heads it holds.
    pub cached_heads: Vec<String>,
    /// (job, index) of every task it holds a lease on.
    pub rendering: Vec<(String, u64)>,
    /// Jobs that stopped giving it tasks after repeated failures.
    pub blocklisted_in: Vec<String>,
}

impl Inner {
    /// The runtime entry of `worker`, created if this is its first call, marked as heard now.
    pub(super) fn seen(&mut self, worker: &str, now: f64) -> &mut WorkerRt {
        let w = self.workers.entry(worker.to_owned()).or_default();
        w.last_seen_unix = Some(now);
        w
    }
}

impl Scheduler {
    /// Loads the persisted workers; none counts as heard from until it calls.
    pub(super) fn load_workers(&self, inner: &mut Inner) -> Result<(), CoordError> {
        for item in self.workers_tree.iter() {
            let (k, v) = item.map_err(sled_err)?;
            let rec: WorkerRecord = serde_json::from_slice(&v).map_err(json_err)?;
            inner.workers.insert(
                String::from_utf8_lossy(&k).into_owned(),
                WorkerRt {
                    rec,
                    ..WorkerRt::default()
                },
            );
        }
        Ok(())
    }

    pub(super) fn persist_worker(&self, name: &str, rec: &WorkerRecord) -> Result<(), CoordError> {
        let v = serde_json::to_vec(rec).map_err(json_err)?;
        self.workers_tree
            .insert(name.as_bytes(), v)
            .map_err(sled_err)?;
        Ok(())
    }

    /// Registers (or re-registers after a restart) a worker. A worker coming back under the
    /// same name lost whatever it was rendering: its old leases are requeued at once instead
    /// of waiting out their deadlines.
    pub fn register_worker(&self, hello: WorkerHello, now: f64) -> Result<String, CoordError> {
        let name = hello.name.as_str();
        if name.is_empty() || name.len() > 200 {
            return Err(CoordError::Invalid(
                "worker name must be 1-200 characters".into(),
            ));
        }
        let mut inner = self.lock();
        let stale: Vec<String> = inner
            .leases
            .iter()
            .filter(|(_, (job, index))| {
                inner
                    .jobs
                    .get(job)
                    .and_then(|j| j.tasks.get(index))
                    .and_then(|t| t.lease.as_ref())
                    .is_some_and(|l| l.worker == name)
            })
            .map(|(id, _)| id.clone())
            .collect();
        for lease in &stale {
            self.release(&mut inner, lease)?;
        }
        let w = inner.seen(name, now);
        w.cached = hello.cached.into_iter().collect();
        w.draining = false;
        w.rec.device = hello.device;
        w.rec.memory_bytes = hello.memory_bytes;
        w.rec.registered_unix = now;
        let rec = w.rec.clone();
        drop(inner);
        self.persist_worker(name, &rec)?;
        if !stale.is_empty() {
            tracing::info!(
                worker = name,
                requeued = stale.len(),
                "worker re-registered; its old leases requeued"
            );
        }
        self.notify();
        Ok(name.to_owned())
    }

    /// The worker said it is shutting down: it finishes what it holds and leases no more.
    pub fn worker_draining(&self, worker: &str, now: f64) {
        let mut inner = self.lock();
        let w = inner.seen(worker, now);
        let changed = !w.draining;
        w.draining = true;
        drop(inner);
        if changed {
            tracing::info!(worker, "worker draining");
            self.notify();
        }
    }

    /// Counts a commit or a failure against `worker`; persisted after the lock is released.
    pub(super) fn count_worker(
        inner: &mut Inner,
        worker: &str,
        now: f64,
        change: impl FnOnce(&mut WorkerRecord),
    ) -> WorkerRecord {
        let w = inner.seen(worker, now);
        change(&mut w.rec);
        w.rec.clone()
    }

    /// Every worker heard from (ever, in this data directory), by name.
    pub fn workers(&self, now: f64) -> Vec<WorkerStatus> {
        let inner = self.lock();
        let heads: Vec<(&str, &str)> = self
            .catalog
            .assets
            .iter()
            .filter(|a| a.kind == AssetKind::Head)
            .map(|a| (a.blake3.as_str(), a.id.as_str()))
            .collect();
        let mut holding: std::collections::HashMap<&str, Vec<(String, u64)>> =
            std::collections::HashMap::new();
        for (job, index) in inner.leases.values() {
            if let Some(l) = inner
                .jobs
                .get(job)
                .and_then(|j| j.tasks.get(index))
                .and_then(|t| t.lease.as_ref())
            {
                holding
                    .entry(l.worker.as_str())
                    .or_default()
                    .push((job.clone(), *index));
            }
        }
        let mut out: Vec<WorkerStatus> = inner
            .workers
            .iter()
            .map(|(name, w)| {
                let mut rendering = holding.remove(name.as_str()).unwrap_or_default();
                rendering.sort();
                let silent = w
                    .last_seen_unix
                    .is_none_or(|t| now - t > self.lease_seconds);
                let state = match (w.draining, silent, rendering.is_empty()) {
                    (true, true, _) | (true, false, true) => WorkerState::Stopped,
                    (false, true, _) => WorkerState::Lost,
                    (true, false, false) => WorkerState::Draining,
                    (false, false, false) => WorkerState::Rendering,
                    (false, false, true) => WorkerState::Idle,
                };
                WorkerStatus {
                    name: name.clone(),
                    device: w.rec.device.clone(),
                    memory_bytes: w.rec.memory_bytes,
                    state,
                    last_seen_unix: w.last_seen_unix,
                    rendered: w.rec.rendered,
                    failures: w.rec.failures,
                    cached_assets: w.cached.len(),
                    cached_heads: heads
                        .iter()
                        .filter(|(hash, _)| w.cached.contains(*hash))
                        .map(|(_, id)| (*id).to_owned())
                        .collect(),
                    rendering,
                    blocklisted_in: inner
                        .jobs
                        .values()
                        .filter(|j| j.rec.blocklist.contains(name))
                        .map(|j| j.rec.id.clone())
                        .collect(),
                }
            })
            .collect();
        out.sort_by(|a, b| a.name.cmp(&b.name));
        out
    }
}
