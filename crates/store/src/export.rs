//! Export of a job's committed samples for training: WebDataset tar shards or a plain folder.
//!
//! Every blob is re-hashed on the way out, because an export is where silent disk corruption
//! would otherwise turn into silently wrong training data.

use std::collections::BTreeSet;
use std::fs::{self, File};
use std::io::{BufRead, BufReader, BufWriter, ErrorKind, Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::blob::{hash_hex, BlobStore, CHUNK};
use crate::index::{SampleIndex, SampleRecord};
use crate::StoreError;

const MANIFEST: &str = "manifest.jsonl";
/// Written before any sample so that an export that died half-way is still recognised as
/// this job's (and may be redone) rather than refused as a foreign directory.
const MARKER: &str = ".lightfarm-export.json";
const TMP_PREFIX: &str = ".";
const TMP_SUFFIX: &str = ".partial";

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ExportFormat {
    /// POSIX tar shards `{job_id}-{shard:06}.tar`; each sample is the adjacent members
    /// `{index:08}.exr` and `{index:08}.json`.
    WebDataset { samples_per_shard: usize },
    /// `{index:08}.exr` + `{index:08}.json` per sample.
    Folder,
}

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExportReport {
    pub samples: u64,
    /// Every file written, `manifest.jsonl` last.
    pub files: Vec<PathBuf>,
    /// Bytes written across those files.
    pub bytes: u64,
}

/// One sample read back from an export.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportedSample {
    pub index: u64,
    /// The sample's JSON: its metadata object plus `job_id`, `index`, `split`, `blake3`, `size`.
    pub json: Value,
    pub exr: Vec<u8>,
}

/// One line of `manifest.jsonl`. Both formats write one, so that a re-export can tell its own
/// directory from a foreign one and remove files the new export no longer produces.
#[derive(Serialize, Deserialize, Clone, Debug)]
struct ManifestLine {
    job_id: String,
    index: u64,
    split: String,
    blake3: String,
    size: u64,
    /// File names relative to the export directory (the shard, for WebDataset).
    files: Vec<String>,
}

#[derive(Serialize, Deserialize)]
struct Marker {
    job_id: String,
}

fn export_err(msg: impl Into<String>) -> StoreError {
    StoreError::Export(msg.into())
}

fn basename(index: u64) -> String {
    format!("{index:08}")
}

/// The job id as it may appear in a file name.
fn file_safe(job_id: &str) -> String {
    job_id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn tmp_name(name: &str) -> String {
    format!("{TMP_PREFIX}{name}{TMP_SUFFIX}")
}

/// Writes `bytes` to `dir/name` via a temp file, so a reader never sees half a file.
fn write_atomic(dir: &Path, name: &str, bytes: &[u8], sync: bool) -> Result<PathBuf, StoreError> {
    let tmp = dir.join(tmp_name(name));
    let dest = dir.join(name);
    let mut f = File::create(&tmp).map_err(|e| StoreError::io(&tmp, e))?;
    f.write_all(bytes).map_err(|e| StoreError::io(&tmp, e))?;
    if sync {
        f.sync_all().map_err(|e| StoreError::io(&tmp, e))?;
    }
    drop(f);
    fs::rename(&tmp, &dest).map_err(|e| StoreError::io(&dest, e))?;
    Ok(dest)
}

fn read_manifest(path: &Path) -> Result<Vec<ManifestLine>, StoreError> {
    let f = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut out = Vec::new();
    for (n, line) in BufReader::new(f).lines().enumerate() {
        let line = line.map_err(|e| StoreError::io(path, e))?;
        if line.trim().is_empty() {
            continue;
        }
        let entry = serde_json::from_str(&line).map_err(|e| {
            export_err(format!(
                "{} line {}: not a lightfarm manifest line ({e})",
                path.display(),
                n + 1
            ))
        })?;
        out.push(entry);
    }
    Ok(out)
}

/// Makes sure `out` may receive an export of `job_id` and returns the file names the previous
/// export of that job left there.
fn prepare_dir(out: &Path, job_id: &str) -> Result<BTreeSet<String>, StoreError> {
    fs::create_dir_all(out).map_err(|e| StoreError::io(out, e))?;
    let mut names = Vec::new();
    for entry in fs::read_dir(out).map_err(|e| StoreError::io(out, e))? {
        let entry = entry.map_err(|e| StoreError::io(out, e))?;
        names.push(entry.file_name().to_string_lossy().into_owned());
    }
    if names.is_empty() {
        return Ok(BTreeSet::new());
    }
    let marker_path = out.join(MARKER);
    let manifest_path = out.join(MANIFEST);
    let marker_job = match fs::read(&marker_path) {
        Ok(b) => serde_json::from_slice::<Marker>(&b).ok().map(|m| m.job_id),
        Err(e) if e.kind() == ErrorKind::NotFound => None,
        Err(e) => return Err(StoreError::io(&marker_path, e)),
    };
    let previous = if manifest_path.exists() {
        read_manifest(&manifest_path)?
    } else {
        Vec::new()
    };
    let owner = marker_job.or_else(|| previous.first().map(|l| l.job_id.clone()));
    match owner {
        Some(owner) if owner == job_id => {}
        Some(owner) => {
            return Err(export_err(format!(
                "{} holds an export of job {owner:?}, not {job_id:?}; export into an empty or \
                 new directory, or delete that one first",
                out.display()
            )))
        }
        None => {
            return Err(export_err(format!(
                "{} is not empty and has no {MANIFEST} from a lightfarm export (it holds {:?}{}); \
                 export into an empty or new directory",
                out.display(),
                names.iter().take(3).collect::<Vec<_>>(),
                if names.len() > 3 { ", …" } else { "" }
            )))
        }
    }
    // Partial files of an export that died are ours and can never be completed.
    for name in &names {
        if name.starts_with(TMP_PREFIX) && name.ends_with(TMP_SUFFIX) {
            let p = out.join(name);
            fs::remove_file(&p).map_err(|e| StoreError::io(&p, e))?;
        }
    }
    Ok(previous
        .into_iter()
        .flat_map(|l| l.files)
        .filter(|f| is_plain_name(f))
        .collect())
}

/// Only bare file names from a manifest are ever deleted, so a crafted manifest can't make a
/// re-export remove files elsewhere.
fn is_plain_name(name: &str) -> bool {
    !name.is_empty()
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\'])
        && name != MANIFEST
        && name != MARKER
}

/// The sample's exported JSON: its metadata object with the index fields added, so a
/// consumer of the JSON alone can check the EXR next to it.
fn sample_json(r: &SampleRecord) -> Value {
    let mut obj = match serde_json::from_str::<Value>(&r.metadata_json) {
        Ok(Value::Object(m)) => m,
        Ok(other) => {
            let mut m = Map::new();
            m.insert("metadata".into(), other);
            m
        }
        Err(e) => {
            tracing::warn!(job = %r.job_id, index = r.index, error = %e, "sample metadata is not JSON; exporting it as a string");
            let mut m = Map::new();
            m.insert("metadata".into(), Value::String(r.metadata_json.clone()));
            m
        }
    };
    obj.insert("job_id".into(), Value::from(r.job_id.clone()));
    obj.insert("index".into(), Value::from(r.index));
    obj.insert("split".into(), Value::from(r.split.clone()));
    obj.insert("blake3".into(), Value::from(r.blake3.clone()));
    obj.insert("size".into(), Value::from(r.size));
    Value::Object(obj)
}

/// Reads a sample's blob and checks it against its record.
fn load_verified(blobs: &dyn BlobStore, r: &SampleRecord) -> Result<Vec<u8>, StoreError> {
    let bytes = blobs.read(&r.blake3).map_err(|e| match e {
        StoreError::NotFound { hash } => export_err(format!(
            "sample {} of job {}: its blob {hash} is missing from the store; nothing past it was \
             exported — restore the blob or re-render the sample",
            r.index, r.job_id
        )),
        other => other,
    })?;
    let got = hash_hex(&bytes);
    if got != r.blake3 || bytes.len() as u64 != r.size {
        return Err(export_err(format!(
            "sample {} of job {}: blob {} is corrupt ({} bytes hashing to {got}, recorded {} \
             bytes); it was not exported — restore the blob or re-render the sample",
            r.index,
            r.job_id,
            r.blake3,
            bytes.len(),
            r.size
        )));
    }
    Ok(bytes)
}

/// A tar shard being written under a temp name; dropped unfinished, it is removed.
struct Shard {
    builder: Option<tar::Builder<BufWriter<File>>>,
    tmp: PathBuf,
    dest: PathBuf,
    name: String,
    samples: usize,
}

impl Shard {
    fn create(out: &Path, name: String) -> Result<Self, StoreError> {
        let tmp = out.join(tmp_name(&name));
        let f = File::create(&tmp).map_err(|e| StoreError::io(&tmp, e))?;
        let mut builder = tar::Builder::new(BufWriter::with_capacity(CHUNK, f));
        builder.mode(tar::HeaderMode::Deterministic);
        Ok(Shard {
            builder: Some(builder),
            tmp,
            dest: out.join(&name),
            name,
            samples: 0,
        })
    }

    fn append(&mut self, name: &str, data: &[u8], mtime: u64) -> Result<(), StoreError> {
        let Some(builder) = self.builder.as_mut() else {
            return Err(export_err(format!("shard {} is already closed", self.name)));
        };
        let mut h = tar::Header::new_ustar();
        h.set_entry_type(tar::EntryType::Regular);
        h.set_size(data.len() as u64);
        h.set_mode(0o644);
        h.set_mtime(mtime);
        h.set_uid(0);
        h.set_gid(0);
        builder
            .append_data(&mut h, name, data)
            .map_err(|e| StoreError::io(&self.tmp, e))
    }

    /// Completes the shard and moves it to its final name; returns its size.
    fn finish(mut self) -> Result<(PathBuf, u64), StoreError> {
        let Some(builder) = self.builder.take() else {
            return Err(export_err(format!("shard {} is already closed", self.name)));
        };
        let buf = builder
            .into_inner()
            .map_err(|e| StoreError::io(&self.tmp, e))?;
        let f = buf
            .into_inner()
            .map_err(|e| StoreError::io(&self.tmp, e.into_error()))?;
        f.sync_all().map_err(|e| StoreError::io(&self.tmp, e))?;
        let size = f
            .metadata()
            .map_err(|e| StoreError::io(&self.tmp, e))?
            .len();
        drop(f);
        fs::rename(&self.tmp, &self.dest).map_err(|e| StoreError::io(&self.dest, e))?;
        Ok((self.dest.clone(), size))
    }
}

impl Drop for Shard {
    fn drop(&mut self) {
        if self.builder.take().is_some() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Writes an export sample by sample, for callers that do not hold the store (a client
/// streaming samples over gRPC); [`export`] is this over a local index.
pub struct ExportWriter {
    out: PathBuf,
    job_id: String,
    format: ExportFormat,
    previous: BTreeSet<String>,
    report: ExportReport,
    manifest: Vec<u8>,
    shard: Option<Shard>,
    shard_no: usize,
    safe_job: String,
}

impl ExportWriter {
    /// Prepares `out` for an export of `job_id`: refuses a non-empty directory that does not
    /// hold an earlier export of the same job, and marks it as this job's.
    pub fn create(
        out: &Path,
        job_id: &str,
        format: &ExportFormat,
    ) -> Result<ExportWriter, StoreError> {
        if let ExportFormat::WebDataset { samples_per_shard } = format {
            if *samples_per_shard == 0 {
                return Err(export_err("samples_per_shard must be at least 1"));
            }
        }
        let previous = prepare_dir(out, job_id)?;
        let marker = serde_json::to_vec(&Marker {
            job_id: job_id.to_owned(),
        })
        .map_err(|e| export_err(format!("encoding the export marker: {e}")))?;
        write_atomic(out, MARKER, &marker, true)?;
        Ok(ExportWriter {
            out: out.to_path_buf(),
            job_id: job_id.to_owned(),
            format: format.clone(),
            previous,
            report: ExportReport::default(),
            manifest: Vec::new(),
            shard: None,
            shard_no: 0,
            safe_job: file_safe(job_id),
        })
    }

    /// Samples written so far.
    pub fn samples(&self) -> u64 {
        self.report.samples
    }

    /// Appends one sample; `exr` must hash to `record.blake3` (corruption is never exported).
    pub fn add(&mut self, record: &SampleRecord, exr: &[u8]) -> Result<(), StoreError> {
        let got = hash_hex(exr);
        if got != record.blake3 || exr.len() as u64 != record.size {
            return Err(StoreError::Corrupt {
                hash: record.blake3.clone(),
                reason: format!(
                    "sample {} of {}: {} bytes hashing to {got}, the index records {} bytes",
                    record.index,
                    record.job_id,
                    exr.len(),
                    record.size
                ),
            });
        }
        let out = self.out.clone();
        let json = serde_json::to_vec(&sample_json(record))
            .map_err(|e| export_err(format!("encoding sample {}'s JSON: {e}", record.index)))?;
        let base = basename(record.index);
        let files = match self.format {
            ExportFormat::WebDataset { samples_per_shard } => {
                if self
                    .shard
                    .as_ref()
                    .is_some_and(|s| s.samples >= samples_per_shard)
                {
                    if let Some(done) = self.shard.take() {
                        let (path, size) = done.finish()?;
                        self.report.bytes += size;
                        self.report.files.push(path);
                    }
                }
                let s = match &mut self.shard {
                    Some(s) => s,
                    None => {
                        let name = format!("{}-{:06}.tar", self.safe_job, self.shard_no);
                        self.shard_no += 1;
                        self.shard.insert(Shard::create(&out, name)?)
                    }
                };
                // Deterministic mtimes keep re-exports byte-identical.
                let mtime = record.committed_unix.max(0.0) as u64;
                s.append(&format!("{base}.exr"), exr, mtime)?;
                s.append(&format!("{base}.json"), &json, mtime)?;
                s.samples += 1;
                vec![s.name.clone()]
            }
            ExportFormat::Folder => {
                let exr_name = format!("{base}.exr");
                let json_name = format!("{base}.json");
                self.report
                    .files
                    .push(write_atomic(&out, &exr_name, exr, false)?);
                self.report
                    .files
                    .push(write_atomic(&out, &json_name, &json, false)?);
                self.report.bytes += (exr.len() + json.len()) as u64;
                vec![exr_name, json_name]
            }
        };
        let line = ManifestLine {
            job_id: record.job_id.clone(),
            index: record.index,
            split: record.split.clone(),
            blake3: record.blake3.clone(),
            size: record.size,
            files,
        };
        serde_json::to_writer(&mut self.manifest, &line)
            .map_err(|e| export_err(format!("encoding the manifest: {e}")))?;
        self.manifest.push(b'\n');
        self.report.samples += 1;
        Ok(())
    }

    /// Closes the last shard, writes `manifest.jsonl` (its presence means the export
    /// completed) and removes files of an earlier export that this one did not write.
    pub fn finish(mut self) -> Result<ExportReport, StoreError> {
        if let Some(done) = self.shard.take() {
            let (path, size) = done.finish()?;
            self.report.bytes += size;
            self.report.files.push(path);
        }
        let written: BTreeSet<String> = self
            .report
            .files
            .iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        let mut report = std::mem::take(&mut self.report);
        report
            .files
            .push(write_atomic(&self.out, MANIFEST, &self.manifest, true)?);
        report.bytes += self.manifest.len() as u64;
        for stale in self.previous.difference(&written) {
            let p = self.out.join(stale);
            match fs::remove_file(&p) {
                Ok(()) => {}
                Err(e) if e.kind() == ErrorKind::NotFound => {}
                Err(e) => return Err(StoreError::io(&p, e)),
            }
        }
        tracing::info!(
            job = %self.job_id,
            samples = report.samples,
            bytes = report.bytes,
            out = %self.out.display(),
            "export finished"
        );
        Ok(report)
    }
}

/// Exports every committed sample of `job_id` from a local index and blob store (re-hashing
/// each blob); `progress(done, total)` is called after each sample.
///
/// Refuses a non-empty `out` that does not hold an earlier export of the same job; an earlier
/// export of the same job is replaced, and files of it that the new one doesn't write are
/// removed. `manifest.jsonl` is written last, so its presence means the export completed.
pub fn export(
    index: &SampleIndex,
    blobs: &dyn BlobStore,
    job_id: &str,
    format: &ExportFormat,
    out: &Path,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ExportReport, StoreError> {
    let mut writer = ExportWriter::create(out, job_id, format)?;
    let total = index.count(job_id)?;
    for record in index.iter_job(job_id) {
        let record = record?;
        let exr = load_verified(blobs, &record)?;
        writer.add(&record, &exr)?;
        progress(writer.samples(), total.max(writer.samples()));
    }
    writer.finish()
}

/// Reads an export back: a folder or WebDataset directory (through its manifest) or a single
/// tar shard. Samples come in export order; every EXR is checked against the `blake3` in its
/// JSON.
pub fn read_export(path: &Path) -> Result<Vec<ExportedSample>, StoreError> {
    let meta = fs::metadata(path).map_err(|e| StoreError::io(path, e))?;
    if meta.is_file() {
        return read_tar(path);
    }
    let manifest_path = path.join(MANIFEST);
    if !manifest_path.exists() {
        return Err(export_err(format!(
            "{} has no {MANIFEST}; the export is missing or did not finish — run it again",
            path.display()
        )));
    }
    let lines = read_manifest(&manifest_path)?;
    let mut out = Vec::with_capacity(lines.len());
    let mut shards_read = BTreeSet::new();
    for line in &lines {
        let tar_name = line.files.iter().find(|f| f.ends_with(".tar"));
        if let Some(tar_name) = tar_name {
            if shards_read.insert(tar_name.clone()) {
                check_manifest_name(path, tar_name)?;
                out.extend(read_tar(&path.join(tar_name))?);
            }
            continue;
        }
        let find = |ext: &str| {
            line.files.iter().find(|f| f.ends_with(ext)).ok_or_else(|| {
                export_err(format!(
                    "{}: sample {} lists no {ext} file",
                    manifest_path.display(),
                    line.index
                ))
            })
        };
        let exr_name = find(".exr")?;
        let json_name = find(".json")?;
        check_manifest_name(path, exr_name)?;
        check_manifest_name(path, json_name)?;
        let exr_path = path.join(exr_name);
        let json_path = path.join(json_name);
        let exr = fs::read(&exr_path).map_err(|e| StoreError::io(&exr_path, e))?;
        let json_bytes = fs::read(&json_path).map_err(|e| StoreError::io(&json_path, e))?;
        out.push(checked_sample(line.index, &json_path, &json_bytes, exr)?);
    }
    Ok(out)
}

/// One sample of a folder export, read on demand: training sets are far larger than memory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExportEntry {
    pub index: u64,
    pub split: String,
    pub exr: PathBuf,
    pub json: PathBuf,
}

impl ExportEntry {
    /// Reads this sample, checking its EXR against the `blake3` in its JSON.
    pub fn read(&self) -> Result<ExportedSample, StoreError> {
        let exr = fs::read(&self.exr).map_err(|e| StoreError::io(&self.exr, e))?;
        let json = fs::read(&self.json).map_err(|e| StoreError::io(&self.json, e))?;
        checked_sample(self.index, &self.json, &json, exr)
    }
}

/// Lists a folder export through its manifest without reading any sample. WebDataset shards
/// are sequential by design and are refused with the command that makes a folder export.
pub fn list_export_folder(path: &Path) -> Result<Vec<ExportEntry>, StoreError> {
    let manifest_path = path.join(MANIFEST);
    if !manifest_path.is_file() {
        return Err(export_err(format!(
            "{} has no {MANIFEST}: not a finished lightfarm export — run `lightfarm export JOB \
             --format folder --out {}`",
            path.display(),
            path.display()
        )));
    }
    let mut out = Vec::new();
    for line in read_manifest(&manifest_path)? {
        if line.files.iter().any(|f| f.ends_with(".tar")) {
            return Err(export_err(format!(
                "{} is a WebDataset export; training reads samples in random order and needs \
                 a folder export: `lightfarm export {} --format folder --out DIR`",
                path.display(),
                line.job_id
            )));
        }
        let find = |ext: &str| -> Result<PathBuf, StoreError> {
            let name = line
                .files
                .iter()
                .find(|f| f.ends_with(ext))
                .ok_or_else(|| {
                    export_err(format!(
                        "{}: sample {} lists no {ext} file",
                        manifest_path.display(),
                        line.index
                    ))
                })?;
            check_manifest_name(path, name)?;
            Ok(path.join(name))
        };
        out.push(ExportEntry {
            index: line.index,
            split: line.split.clone(),
            exr: find(".exr")?,
            json: find(".json")?,
        });
    }
    Ok(out)
}

fn check_manifest_name(dir: &Path, name: &str) -> Result<(), StoreError> {
    if is_plain_name(name) {
        Ok(())
    } else {
        Err(export_err(format!(
            "{}: manifest names {name:?}, which is not a file in that directory",
            dir.display()
        )))
    }
}

fn checked_sample(
    index: u64,
    json_path: &Path,
    json_bytes: &[u8],
    exr: Vec<u8>,
) -> Result<ExportedSample, StoreError> {
    let json: Value = serde_json::from_slice(json_bytes)
        .map_err(|e| export_err(format!("{}: not JSON ({e})", json_path.display())))?;
    if let Some(expected) = json.get("blake3").and_then(Value::as_str) {
        let got = hash_hex(&exr);
        if got != expected {
            return Err(StoreError::Corrupt {
                hash: expected.to_owned(),
                reason: format!(
                    "the EXR of sample {index} next to {} hashes to {got}; the export was \
                     damaged — export again",
                    json_path.display()
                ),
            });
        }
    }
    Ok(ExportedSample { index, json, exr })
}

/// Reads a WebDataset shard, enforcing its rule that a sample's members are adjacent.
fn read_tar(path: &Path) -> Result<Vec<ExportedSample>, StoreError> {
    let f = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut archive = tar::Archive::new(BufReader::with_capacity(CHUNK, f));
    // Groups are validated only after the whole shard is read, so a misplaced member is
    // reported as such rather than as the incomplete sample it leaves behind.
    let mut groups: Vec<MemberGroup> = Vec::new();
    let mut seen = BTreeSet::new();
    let entries = archive.entries().map_err(|e| StoreError::io(path, e))?;
    for entry in entries {
        let mut entry = entry.map_err(|e| StoreError::io(path, e))?;
        let name = entry
            .path()
            .map_err(|e| StoreError::io(path, e))?
            .to_string_lossy()
            .into_owned();
        let (key, ext) = name.split_once('.').ok_or_else(|| {
            export_err(format!(
                "{}: member {name:?} has no extension",
                path.display()
            ))
        })?;
        let mut data = Vec::new();
        entry
            .read_to_end(&mut data)
            .map_err(|e| StoreError::io(path, e))?;
        if groups.last().is_none_or(|g| g.key != key) {
            if !seen.insert(key.to_owned()) {
                return Err(export_err(format!(
                    "{}: members of sample {key} are not adjacent; this is not a valid \
                     WebDataset shard",
                    path.display()
                )));
            }
            groups.push(MemberGroup {
                key: key.to_owned(),
                exr: None,
                json: None,
            });
        }
        if let Some(g) = groups.last_mut() {
            match ext {
                "exr" => g.exr = Some(data),
                "json" => g.json = Some(data),
                other => tracing::debug!(member = %name, ext = other, "ignoring an unknown member"),
            }
        }
    }
    groups
        .into_iter()
        .map(|g| finish_member_group(path, g))
        .collect()
}

struct MemberGroup {
    key: String,
    exr: Option<Vec<u8>>,
    json: Option<Vec<u8>>,
}

fn finish_member_group(path: &Path, group: MemberGroup) -> Result<ExportedSample, StoreError> {
    let MemberGroup { key, exr, json } = group;
    let index: u64 = key.parse().map_err(|_| {
        export_err(format!(
            "{}: member key {key:?} is not a sample index",
            path.display()
        ))
    })?;
    let (Some(exr), Some(json)) = (exr, json) else {
        return Err(export_err(format!(
            "{}: sample {key} needs both {key}.exr and {key}.json",
            path.display()
        )));
    };
    let json_path = path.join(format!("{key}.json"));
    checked_sample(index, &json_path, &json, exr)
}
