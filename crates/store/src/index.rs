use std::sync::Arc;

use serde::{Deserialize, Serialize};
use sled::transaction::{ConflictableTransactionError, TransactionError};
use sled::Transactional;
use tokio::sync::watch;

use crate::blob::check_hash;
use crate::StoreError;

// Tree names share the coordinator's `sled::Db`, so they carry a "samples" prefix to stay clear
// of its "jobs"/"tasks" trees.
const SAMPLES_TREE: &str = "samples";
const BY_SEQ_TREE: &str = "samples_by_seq";
const COUNTS_TREE: &str = "samples_count";
const META_TREE: &str = "samples_meta";
const NEXT_SEQUENCE: &[u8] = b"next_sequence";

/// Sequences start at 1 so that 0 can mean "nothing committed yet" in [`SampleIndex::subscribe`]
/// and a cursor of 0 means "from the beginning".
const FIRST_SEQUENCE: u64 = 1;

/// A committed sample's index record (JSON in sled).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SampleRecord {
    pub job_id: String,
    pub index: u64,
    pub split: String,
    /// Hash of the sample's EXR in the blob store.
    pub blake3: String,
    pub size: u64,
    pub metadata_json: String,
    pub committed_unix: f64,
    /// Position in the global commit order, from 1, unique across jobs.
    pub sequence: u64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum CommitOutcome {
    /// This call committed the sample.
    Committed(SampleRecord),
    /// The sample was already committed (by an earlier upload); nothing changed.
    AlreadyCommitted(SampleRecord),
}

impl CommitOutcome {
    pub fn record(&self) -> &SampleRecord {
        match self {
            CommitOutcome::Committed(r) | CommitOutcome::AlreadyCommitted(r) => r,
        }
    }

    pub fn into_record(self) -> SampleRecord {
        match self {
            CommitOutcome::Committed(r) | CommitOutcome::AlreadyCommitted(r) => r,
        }
    }

    pub fn is_new(&self) -> bool {
        matches!(self, CommitOutcome::Committed(_))
    }
}

/// The sled index of committed samples: the only authority on whether a sample is done.
///
/// Trees (in the `sled::Db` handed to [`SampleIndex::open`]):
/// - `samples`: `job_id 0x00 index(u64 BE)` → JSON [`SampleRecord`], so a job's samples
///   iterate in index order;
/// - `samples_by_seq`: `sequence(u64 BE)` → primary key, the commit order;
/// - `samples_count`: `job_id` → committed count (u64 BE);
/// - `samples_meta`: `next_sequence` → u64 BE.
///
/// All four change in one sled transaction, so a crash can neither lose a sample from the
/// commit order nor commit one twice. A commit is durable once the db is flushed
/// (`Db::flush`/`flush_async`, or sled's periodic flush); callers that acknowledge uploads
/// flush first.
///
/// Clones share the same trees and the same [`SampleIndex::subscribe`] channel.
#[derive(Clone)]
pub struct SampleIndex {
    db: sled::Db,
    samples: sled::Tree,
    by_seq: sled::Tree,
    counts: sled::Tree,
    meta: sled::Tree,
    latest: Arc<watch::Sender<u64>>,
    /// Commits take this first. Every commit reads and bumps the same sequence counter, so
    /// concurrent sled transactions would all conflict and retry; queueing them on a lock
    /// costs less (a commit holds it for microseconds). Clones share it.
    commit_lock: Arc<std::sync::Mutex<()>>,
}

fn job_prefix(job_id: &str) -> Vec<u8> {
    let mut k = Vec::with_capacity(job_id.len() + 9);
    k.extend_from_slice(job_id.as_bytes());
    k.push(0);
    k
}

fn sample_key(job_id: &str, index: u64) -> Vec<u8> {
    let mut k = job_prefix(job_id);
    k.extend_from_slice(&index.to_be_bytes());
    k
}

fn decode_u64(bytes: &[u8], what: &str) -> Result<u64, StoreError> {
    let arr: [u8; 8] = bytes.try_into().map_err(|_| {
        StoreError::Sled(format!(
            "{what} is {} bytes, not 8; the samples trees were written by something else",
            bytes.len()
        ))
    })?;
    Ok(u64::from_be_bytes(arr))
}

fn decode_record(bytes: &[u8]) -> Result<SampleRecord, StoreError> {
    serde_json::from_slice(bytes)
        .map_err(|e| StoreError::Sled(format!("a sample record is not valid JSON ({e})")))
}

fn check_job_id(job_id: &str) -> Result<(), StoreError> {
    // The NUL separates job id from index in keys; allowing it would let one job's prefix
    // scan see another's samples.
    if job_id.is_empty() || job_id.contains('\0') {
        return Err(StoreError::Invalid(format!(
            "job id {job_id:?} must be non-empty and contain no NUL character"
        )));
    }
    Ok(())
}

impl SampleIndex {
    /// Opens the index's trees in `db` (which the coordinator shares for its own trees).
    pub fn open(db: &sled::Db) -> Result<Self, StoreError> {
        let samples = db.open_tree(SAMPLES_TREE)?;
        let by_seq = db.open_tree(BY_SEQ_TREE)?;
        let counts = db.open_tree(COUNTS_TREE)?;
        let meta = db.open_tree(META_TREE)?;
        let latest = match by_seq.last()? {
            Some((k, _)) => decode_u64(&k, "a sequence key")?,
            None => 0,
        };
        let (tx, _) = watch::channel(latest);
        Ok(SampleIndex {
            db: db.clone(),
            samples,
            by_seq,
            counts,
            meta,
            latest: Arc::new(tx),
            commit_lock: Arc::new(std::sync::Mutex::new(())),
        })
    }

    /// Exactly-once commit: records (job_id, index) with the next sequence number unless it is
    /// already committed, in which case the existing record is returned untouched.
    #[allow(clippy::too_many_arguments)]
    pub fn commit(
        &self,
        job_id: &str,
        index: u64,
        split: &str,
        blake3: &str,
        size: u64,
        metadata_json: &str,
        now_unix: f64,
    ) -> Result<CommitOutcome, StoreError> {
        check_job_id(job_id)?;
        check_hash(blake3)?;
        if !now_unix.is_finite() {
            // JSON has no NaN/inf, so such a record could never be read back.
            return Err(StoreError::Invalid(format!(
                "commit time {now_unix} of sample {index} of job {job_id} is not a finite number"
            )));
        }
        let key = sample_key(job_id, index);
        let template = SampleRecord {
            job_id: job_id.to_owned(),
            index,
            split: split.to_owned(),
            blake3: blake3.to_owned(),
            size,
            metadata_json: metadata_json.to_owned(),
            committed_unix: now_unix,
            sequence: 0,
        };
        // A poisoned lock only means another commit panicked; the transaction below is still
        // all-or-nothing, so carry on.
        let _serial = self.commit_lock.lock().unwrap_or_else(|p| p.into_inner());
        let result = (&self.samples, &self.by_seq, &self.counts, &self.meta).transaction(
            |(samples, by_seq, counts, meta)| {
                if let Some(existing) = samples.get(&key)? {
                    let existing =
                        decode_record(&existing).map_err(ConflictableTransactionError::Abort)?;
                    return Ok(CommitOutcome::AlreadyCommitted(existing));
                }
                let sequence = match meta.get(NEXT_SEQUENCE)? {
                    Some(v) => decode_u64(&v, "next_sequence")
                        .map_err(ConflictableTransactionError::Abort)?,
                    None => FIRST_SEQUENCE,
                };
                let count = match counts.get(job_id.as_bytes())? {
                    Some(v) => decode_u64(&v, "a job's count")
                        .map_err(ConflictableTransactionError::Abort)?,
                    None => 0,
                };
                let mut record = template.clone();
                record.sequence = sequence;
                let json = serde_json::to_vec(&record).map_err(|e| {
                    ConflictableTransactionError::Abort(StoreError::Sled(format!(
                        "encoding the record of sample {index} of job {job_id}: {e}"
                    )))
                })?;
                samples.insert(key.as_slice(), json)?;
                by_seq.insert(&sequence.to_be_bytes(), key.as_slice())?;
                counts.insert(job_id.as_bytes(), &(count + 1).to_be_bytes())?;
                meta.insert(NEXT_SEQUENCE, &(sequence + 1).to_be_bytes())?;
                Ok(CommitOutcome::Committed(record))
            },
        );
        let outcome = match result {
            Ok(o) => o,
            Err(TransactionError::Abort(e)) => return Err(e),
            Err(TransactionError::Storage(e)) => return Err(e.into()),
        };
        match &outcome {
            CommitOutcome::Committed(r) => {
                tracing::debug!(
                    job = job_id,
                    index,
                    sequence = r.sequence,
                    "sample committed"
                );
                let seq = r.sequence;
                // Concurrent commits can finish out of order; never move the latest backwards.
                self.latest.send_if_modified(|v| {
                    if seq > *v {
                        *v = seq;
                        true
                    } else {
                        false
                    }
                });
            }
            CommitOutcome::AlreadyCommitted(r) => {
                tracing::debug!(
                    job = job_id,
                    index,
                    sequence = r.sequence,
                    "sample was already committed"
                );
            }
        }
        Ok(outcome)
    }

    pub fn get(&self, job_id: &str, index: u64) -> Result<Option<SampleRecord>, StoreError> {
        match self.samples.get(sample_key(job_id, index))? {
            Some(v) => Ok(Some(decode_record(&v)?)),
            None => Ok(None),
        }
    }

    pub fn is_committed(&self, job_id: &str, index: u64) -> Result<bool, StoreError> {
        Ok(self.samples.contains_key(sample_key(job_id, index))?)
    }

    /// Records ordered by (job_id, index), optionally filtered; skips `offset` matching
    /// records and returns up to `limit`, plus the total number matching.
    pub fn list(
        &self,
        job_id: Option<&str>,
        split: Option<&str>,
        offset: u64,
        limit: usize,
    ) -> Result<(Vec<SampleRecord>, u64), StoreError> {
        let iter = match job_id {
            Some(j) => self.samples.scan_prefix(job_prefix(j)),
            None => self.samples.iter(),
        };
        let mut out = Vec::new();
        let mut total = 0u64;
        for item in iter {
            let (_, v) = item?;
            let in_window = total >= offset && out.len() < limit;
            match split {
                // Without a split filter, records outside the window only need counting.
                None if !in_window => {}
                None => out.push(decode_record(&v)?),
                Some(s) => {
                    let rec = decode_record(&v)?;
                    if rec.split != s {
                        continue;
                    }
                    if in_window {
                        out.push(rec);
                    }
                }
            }
            total += 1;
        }
        Ok((out, total))
    }

    /// A job's records in index order, read lazily (for exports of any size).
    pub fn iter_job<'a>(
        &'a self,
        job_id: &str,
    ) -> impl Iterator<Item = Result<SampleRecord, StoreError>> + 'a {
        self.samples
            .scan_prefix(job_prefix(job_id))
            .map(|item| decode_record(&item?.1))
    }

    /// Records in commit order with `sequence >= cursor`, filtered, up to `limit`. A reader
    /// resumes with `cursor = last.sequence + 1`.
    pub fn since(
        &self,
        cursor: u64,
        job_id: Option<&str>,
        split: Option<&str>,
        limit: usize,
    ) -> Result<Vec<SampleRecord>, StoreError> {
        let prefix = job_id.map(job_prefix);
        let mut out = Vec::new();
        if limit == 0 {
            return Ok(out);
        }
        for item in self.by_seq.range(cursor.to_be_bytes()..) {
            let (seq, key) = item?;
            if let Some(p) = &prefix {
                // The primary key starts with the job, so other jobs are skipped unread.
                if !key.starts_with(p) {
                    continue;
                }
            }
            let Some(v) = self.samples.get(&key)? else {
                // Both trees change in one transaction, so this means outside interference.
                return Err(StoreError::Sled(format!(
                    "sequence {} points at a sample record that does not exist",
                    decode_u64(&seq, "a sequence key")?
                )));
            };
            let rec = decode_record(&v)?;
            if split.is_some_and(|s| rec.split != s) {
                continue;
            }
            out.push(rec);
            if out.len() >= limit {
                break;
            }
        }
        Ok(out)
    }

    /// Number of committed samples of a job.
    pub fn count(&self, job_id: &str) -> Result<u64, StoreError> {
        match self.counts.get(job_id.as_bytes())? {
            Some(v) => decode_u64(&v, "a job's count"),
            None => Ok(0),
        }
    }

    /// Number of committed samples of every job together. Reads one counter per job rather
    /// than the records, so it stays cheap however many samples there are.
    pub fn total_count(&self) -> Result<u64, StoreError> {
        let mut total = 0u64;
        for item in self.counts.iter() {
            let (_, v) = item?;
            total = total.saturating_add(decode_u64(&v, "a job's count")?);
        }
        Ok(total)
    }

    /// Sequence of the newest commit, 0 if none.
    pub fn latest_sequence(&self) -> u64 {
        *self.latest.borrow()
    }

    /// A receiver of the latest committed sequence (0 before the first commit). Its
    /// `changed().await` resolves after a commit made through this index or a clone of it,
    /// without blocking a runtime thread. Subscribe *before* reading with
    /// [`SampleIndex::since`] so that a commit in between is not missed.
    pub fn subscribe(&self) -> watch::Receiver<u64> {
        self.latest.subscribe()
    }

    /// Flushes the db so every commit so far survives a crash.
    pub fn flush(&self) -> Result<(), StoreError> {
        self.db.flush()?;
        Ok(())
    }
}
