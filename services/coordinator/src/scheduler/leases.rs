//! The task life cycle under the scheduler's lock: leasing (priority, age, locality),
//! heartbeats, expiry, the fenced upload check, commits and failures with their retry and
//! blocklist rules (see the parent module's docs for the semantics).

use std::collections::HashSet;

use lightfarm_scene::expand::{expand, required_assets};

use super::{
    compact_json, json_err, ms, sled_err, task_key, Failure, Inner, JobRt, Lease, LeasedTask,
    RunState, Scheduler, UploadCheck, BLOCKLIST_AFTER, MAX_FAILED_WORKERS, RATE_WINDOW_S,
    RECENT_FAILURES,
};
use crate::error::CoordError;

impl Scheduler {
    /// Requeues the task of `lease` (expired or abandoned); not a failure.
    pub(super) fn release(&self, inner: &mut Inner, lease: &str) -> Result<(), CoordError> {
        let Some((job_id, index)) = inner.leases.remove(lease) else {
            return Ok(());
        };
        let Some(job) = inner.jobs.get_mut(&job_id) else {
            return Ok(());
        };
        let Some(task) = job.tasks.get_mut(&index) else {
            return Ok(());
        };
        if let Some(l) = task.lease.take() {
            inner.deadlines.remove(&(ms(l.deadline_unix), l.id));
            job.leased = job.leased.saturating_sub(1);
        }
        let task = task.clone();
        job.enqueue(index);
        self.persist_task(&job_id, index, Some(&task))
    }

    /// Leases up to `capacity` tasks to `worker`: highest priority first, then oldest job;
    /// within a job, samples whose head the worker has cached first, then in index order;
    /// never a task this worker already failed, never from a job that blocklisted it.
    pub fn lease(
        &self,
        worker: &str,
        capacity: u32,
        cached: Option<Vec<String>>,
        now: f64,
    ) -> Result<Vec<LeasedTask>, CoordError> {
        let mut inner = self.lock();
        let w = inner.seen(worker, now);
        if let Some(c) = cached {
            w.cached = c.into_iter().collect();
        }
        let cached: HashSet<String> = w.cached.clone();
        let mut order: Vec<(i32, u64, String)> = inner
            .jobs
            .values()
            .filter(|j| j.rec.run == RunState::Running && !j.queued.is_empty())
            .filter(|j| !j.rec.blocklist.contains(worker))
            .map(|j| (-j.rec.priority, j.rec.seq, j.rec.id.clone()))
            .collect();
        order.sort();
        let deadline = now + self.lease_seconds;
        let mut out = Vec::new();
        let mut batch = sled::Batch::default();
        for (_, _, job_id) in order {
            if out.len() >= capacity as usize {
                break;
            }
            let Inner {
                jobs,
                leases,
                deadlines,
                ..
            } = &mut *inner;
            let Some(job) = jobs.get_mut(&job_id) else {
                continue;
            };
            let want = capacity as usize - out.len();
            let failed_here = |job: &JobRt, i: u64| {
                job.tasks
                    .get(&i)
                    .is_some_and(|t| t.failures.iter().any(|f| f.worker == worker))
            };
            let mut picked: Vec<u64> = Vec::new();
            // Locality first: heads this worker holds.
            let local_heads: Vec<u32> = job
                .heads
                .iter()
                .enumerate()
                .filter(|(_, h)| cached.contains(*h))
                .map(|(i, _)| i as u32)
                .collect();
            for h in local_heads {
                let Some(set) = job.by_head.get(&h) else {
                    continue;
                };
                for &i in set.iter() {
                    if picked.len() >= want {
                        break;
                    }
                    if !failed_here(job, i) {
                        picked.push(i);
                    }
                }
            }
            if picked.len() < want {
                let chosen: HashSet<u64> = picked.iter().copied().collect();
                for &i in job.queued.iter() {
                    if picked.len() >= want {
                        break;
                    }
                    if !chosen.contains(&i) && !failed_here(job, i) {
                        picked.push(i);
                    }
                }
            }
            for index in picked {
                job.dequeue(index);
                let task = job.tasks.entry(index).or_default();
                task.attempt += 1;
                let lease = Lease {
                    id: format!("{job_id}.{index}.{}", task.attempt),
                    worker: worker.to_owned(),
                    deadline_unix: deadline,
                };
                task.lease = Some(lease.clone());
                let v = serde_json::to_vec(&*task).map_err(json_err)?;
                batch.insert(task_key(&job_id, index), v);
                job.leased += 1;
                leases.insert(lease.id.clone(), (job_id.clone(), index));
                deadlines.insert((ms(deadline), lease.id.clone()));
                let sample =
                    expand(&job.spec, index).map_err(|e| CoordError::BadSpec(e.to_string()))?;
                let sample_json = compact_json(&sample)?;
                let assets = required_assets(&sample, &self.catalog)
                    .map_err(|e| CoordError::BadSpec(e.to_string()))?
                    .into_iter()
                    .map(|a| (a.id.clone(), a.blake3.clone()))
                    .collect();
                out.push(LeasedTask {
                    job_id: job_id.clone(),
                    index,
                    lease_id: lease.id,
                    deadline_unix: deadline,
                    sample_json,
                    assets,
                });
            }
        }
        drop(inner);
        if !out.is_empty() {
            self.tasks_tree.apply_batch(batch).map_err(sled_err)?;
            self.notify();
        }
        Ok(out)
    }

    /// Extends `worker`'s leases; returns the ones it no longer holds.
    pub fn heartbeat(
        &self,
        worker: &str,
        leases: &[String],
        now: f64,
    ) -> Result<(Vec<String>, f64), CoordError> {
        let mut inner = self.lock();
        inner.seen(worker, now);
        let deadline = now + self.lease_seconds;
        let mut lost = Vec::new();
        let mut batch = sled::Batch::default();
        for id in leases {
            let Some((job_id, index)) = inner.leases.get(id).cloned() else {
                lost.push(id.clone());
                continue;
            };
            let Inner {
                jobs, deadlines, ..
            } = &mut *inner;
            let Some(job) = jobs.get_mut(&job_id) else {
                lost.push(id.clone());
                continue;
            };
            let running = job.rec.run != RunState::Cancelled;
            match job.tasks.get_mut(&index).and_then(|t| t.lease.as_mut()) {
                Some(l) if l.worker == worker && running => {
                    deadlines.remove(&(ms(l.deadline_unix), l.id.clone()));
                    l.deadline_unix = deadline;
                    deadlines.insert((ms(deadline), l.id.clone()));
                    if let Some(t) = job.tasks.get(&index) {
                        batch.insert(
                            task_key(&job_id, index),
                            serde_json::to_vec(t).map_err(json_err)?,
                        );
                    }
                }
                _ => lost.push(id.clone()),
            }
        }
        drop(inner);
        self.tasks_tree.apply_batch(batch).map_err(sled_err)?;
        Ok((lost, deadline))
    }

    /// Requeues every lease whose deadline passed; returns how many.
    pub fn expire(&self, now: f64) -> Result<usize, CoordError> {
        let mut inner = self.lock();
        let cut = ms(now);
        let expired: Vec<String> = inner
            .deadlines
            .iter()
            .take_while(|(d, _)| *d < cut)
            .map(|(_, id)| id.clone())
            .collect();
        for id in &expired {
            tracing::info!(lease = %id, "lease expired; task requeued");
            self.release(&mut inner, id)?;
        }
        drop(inner);
        if !expired.is_empty() {
            self.notify();
        }
        Ok(expired.len())
    }

    /// Decides whether `worker` may upload sample (job, index) under `lease_id`.
    pub fn check_upload(
        &self,
        worker: &str,
        lease_id: &str,
        job_id: &str,
        index: u64,
    ) -> Result<UploadCheck, CoordError> {
        if self.samples.is_committed(job_id, index)? {
            return Ok(UploadCheck::AlreadyCommitted);
        }
        let inner = self.lock();
        let job = inner
            .jobs
            .get(job_id)
            .ok_or_else(|| CoordError::UnknownJob(job_id.to_owned()))?;
        if index >= job.rec.count {
            return Err(CoordError::Invalid(format!(
                "sample {index} does not exist in job {job_id} ({} samples)",
                job.rec.count
            )));
        }
        if job.rec.run == RunState::Cancelled {
            return Err(CoordError::Conflict(format!("job {job_id} was cancelled")));
        }
        let task = job.tasks.get(&index);
        if task.is_some_and(|t| t.failed) {
            return Err(CoordError::Conflict(format!(
                "sample {index} of {job_id} was failed after {MAX_FAILED_WORKERS} workers failed it"
            )));
        }
        match task.and_then(|t| t.lease.as_ref()) {
            Some(l) if l.id == lease_id && l.worker == worker => {}
            // Held by someone else now: fenced off.
            Some(l) => {
                return Err(CoordError::LeaseLost(format!(
                    "lease {lease_id} is no longer current for sample {index} of {job_id} \
                     (now {} held by {}); drop this result",
                    l.id, l.worker
                )))
            }
            // Expired and not re-leased: the deterministic result is welcome.
            None => {}
        }
        let sample = expand(&job.spec, index).map_err(|e| CoordError::BadSpec(e.to_string()))?;
        let sample_json = compact_json(&sample)?;
        Ok(UploadCheck::Accept {
            split: match sample.split {
                lightfarm_scene::expand::Split::Train => "train".into(),
                lightfarm_scene::expand::Split::Test => "test".into(),
            },
            sample_json,
        })
    }

    /// Records that (job, index), uploaded by `worker`, was committed to the sample index.
    pub fn mark_done(
        &self,
        job_id: &str,
        index: u64,
        worker: &str,
        now: f64,
    ) -> Result<(), CoordError> {
        let mut inner = self.lock();
        let counted = Self::count_worker(&mut inner, worker, now, |w| w.rendered += 1);
        let Inner {
            jobs,
            leases,
            deadlines,
            ..
        } = &mut *inner;
        let Some(job) = jobs.get_mut(job_id) else {
            return Ok(());
        };
        job.dequeue(index);
        if let Some(task) = job.tasks.remove(&index) {
            if let Some(l) = task.lease {
                leases.remove(&l.id);
                deadlines.remove(&(ms(l.deadline_unix), l.id));
                job.leased = job.leased.saturating_sub(1);
            }
        }
        job.done += 1;
        job.commits.push_back(now);
        while job.commits.front().is_some_and(|t| now - t > RATE_WINDOW_S) {
            job.commits.pop_front();
        }
        drop(inner);
        self.persist_worker(worker, &counted)?;
        // The task's sled record is left behind: the sample index says "done" and wins at
        // recovery, which also deletes such records (one write fewer per commit).
        self.notify();
        Ok(())
    }

    /// A worker reports it could not render its leased task. Returns whether it will be retried.
    pub fn fail(
        &self,
        worker: &str,
        lease_id: &str,
        reason: &str,
        now: f64,
    ) -> Result<bool, CoordError> {
        let mut inner = self.lock();
        let Some((job_id, index)) = inner.leases.get(lease_id).cloned() else {
            return Err(CoordError::LeaseLost(format!(
                "lease {lease_id} is not current (expired or already finished)"
            )));
        };
        let Inner {
            jobs,
            leases,
            deadlines,
            ..
        } = &mut *inner;
        let Some(job) = jobs.get_mut(&job_id) else {
            return Err(CoordError::UnknownJob(job_id));
        };
        let Some(task) = job.tasks.get_mut(&index) else {
            return Err(CoordError::LeaseLost(format!(
                "lease {lease_id} is not current"
            )));
        };
        if task.lease.as_ref().is_none_or(|l| l.worker != worker) {
            return Err(CoordError::LeaseLost(format!(
                "lease {lease_id} is not held by {worker}"
            )));
        }
        if let Some(l) = task.lease.take() {
            leases.remove(&l.id);
            deadlines.remove(&(ms(l.deadline_unix), l.id));
            job.leased = job.leased.saturating_sub(1);
        }
        let failure = Failure {
            worker: worker.to_owned(),
            reason: reason.chars().take(4000).collect(),
            at_unix: now,
        };
        task.failures.push(failure.clone());
        let distinct: HashSet<&str> = task.failures.iter().map(|f| f.worker.as_str()).collect();
        let retry = distinct.len() < MAX_FAILED_WORKERS;
        if !retry {
            task.failed = true;
        }
        let task = task.clone();
        job.recent.push_back((index, failure));
        while job.recent.len() > RECENT_FAILURES {
            job.recent.pop_front();
        }
        if retry {
            job.enqueue(index);
        } else {
            job.failed += 1;
            tracing::warn!(job = %job_id, index, "task failed on {MAX_FAILED_WORKERS} workers; giving up");
        }
        let n = job.worker_failures.entry(worker.to_owned()).or_default();
        *n += 1;
        let blocklisted = *n >= BLOCKLIST_AFTER && job.rec.blocklist.insert(worker.to_owned());
        let rec = job.rec.clone();
        let counted = Self::count_worker(&mut inner, worker, now, |w| w.failures += 1);
        drop(inner);
        self.persist_worker(worker, &counted)?;
        self.persist_task(&job_id, index, Some(&task))?;
        if blocklisted {
            tracing::warn!(job = %job_id, worker, "worker blocklisted for this job after repeated failures");
            self.persist_job(&rec)?;
        }
        self.notify();
        Ok(retry)
    }
}
