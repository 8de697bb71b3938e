//! The trainer's on-disk cache of samples fetched from a coordinator: one `<index>.exr` per
//! sample, bounded in bytes, least recently used first out. It holds the EXRs as the store
//! keeps them (compressed): decoding is cheap next to a network fetch, and decoded f32 images
//! would take four to eight times the disk.
//!
//! A file is trusted only if its size and BLAKE3 match what the coordinator committed, so a
//! cache left by a killed process (a half-written file, another job's samples) is harmless.

use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::TrainError;

/// A committed sample as the trainer knows it: enough to verify a cached copy.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SampleRef {
    pub index: u64,
    pub blake3: String,
    pub size: u64,
}

pub struct SampleCache {
    dir: PathBuf,
    capacity: u64,
    state: Mutex<State>,
}

#[derive(Default)]
struct State {
    /// index → (bytes, last use)
    files: HashMap<u64, (u64, u64)>,
    total: u64,
    clock: u64,
}

impl SampleCache {
    /// Opens `dir` (creating it), adopting the files a previous run left, oldest first.
    pub fn open(dir: &Path, capacity: u64) -> Result<SampleCache, TrainError> {
        fs::create_dir_all(dir).map_err(|e| TrainError::io(dir, e))?;
        let mut found = Vec::new();
        for entry in fs::read_dir(dir)
            .map_err(|e| TrainError::io(dir, e))?
            .flatten()
        {
            let name = entry.file_name().to_string_lossy().into_owned();
            let Some(index) = name
                .strip_suffix(".exr")
                .and_then(|n| n.parse::<u64>().ok())
            else {
                // Temporary files of a killed writer.
                if name.ends_with(".tmp") {
                    let _ = fs::remove_file(entry.path());
                }
                continue;
            };
            if let Ok(meta) = entry.metadata() {
                found.push((meta.modified().ok(), index, meta.len()));
            }
        }
        found.sort();
        let mut state = State::default();
        for (_, index, len) in found {
            state.clock += 1;
            state.files.insert(index, (len, state.clock));
            state.total += len;
        }
        let cache = SampleCache {
            dir: dir.to_owned(),
            capacity,
            state: Mutex::new(state),
        };
        cache.evict(None);
        Ok(cache)
    }

    fn path(&self, index: u64) -> PathBuf {
        self.dir.join(format!("{index}.exr"))
    }

    /// The cached bytes of `sample` if present and intact.
    pub fn get(&self, sample: &SampleRef) -> Option<Vec<u8>> {
        if !self.lock().files.contains_key(&sample.index) {
            return None;
        }
        let bytes = fs::read(self.path(sample.index)).ok();
        match bytes {
            Some(b)
                if b.len() as u64 == sample.size
                    && blake3::hash(&b).to_hex().as_str() == sample.blake3 =>
            {
                let mut s = self.lock();
                s.clock += 1;
                let clock = s.clock;
                if let Some(e) = s.files.get_mut(&sample.index) {
                    e.1 = clock;
                }
                Some(b)
            }
            _ => {
                self.forget(sample.index);
                None
            }
        }
    }

    /// Stores `bytes` as `sample` (checked by the caller), evicting the least recently used
    /// others beyond the capacity. A failed write only costs a later refetch.
    pub fn put(&self, sample: &SampleRef, bytes: &[u8]) {
        let path = self.path(sample.index);
        let tmp = self.dir.join(format!("{}.tmp", sample.index));
        if let Err(e) = fs::write(&tmp, bytes).and_then(|_| fs::rename(&tmp, &path)) {
            tracing::warn!(
                "sample cache {}: {e}; the sample will be fetched again",
                path.display()
            );
            let _ = fs::remove_file(&tmp);
            return;
        }
        {
            let mut s = self.lock();
            s.clock += 1;
            let clock = s.clock;
            if let Some((old, _)) = s.files.insert(sample.index, (bytes.len() as u64, clock)) {
                s.total -= old;
            }
            s.total += bytes.len() as u64;
        }
        self.evict(Some(sample.index));
    }

    pub fn bytes(&self) -> u64 {
        self.lock().total
    }

    pub fn contains(&self, index: u64) -> bool {
        self.lock().files.contains_key(&index)
    }

    fn forget(&self, index: u64) {
        let mut s = self.lock();
        if let Some((len, _)) = s.files.remove(&index) {
            s.total -= len;
        }
        drop(s);
        let _ = fs::remove_file(self.path(index));
    }

    fn evict(&self, keep: Option<u64>) {
        loop {
            let victim = {
                let s = self.lock();
                if s.total <= self.capacity {
                    return;
                }
                s.files
                    .iter()
                    .filter(|(i, _)| Some(**i) != keep)
                    .min_by_key(|(_, (_, used))| *used)
                    .map(|(i, _)| *i)
            };
            match victim {
                Some(i) => self.forget(i),
                None => return,
            }
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}
