//! Finished samples waiting for upload: `<job>__<index>.exr` plus its header `.json`. The JSON
//! is written last by atomic rename, so an entry either is complete or is not an entry.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use lightfarm_proto::v1 as pb;
use serde::{Deserialize, Serialize};
use tonic::Code;

use crate::client::Client;

const CHUNK: usize = 1 << 20;

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct OutboxEntry {
    pub worker_id: String,
    pub lease_id: String,
    pub job_id: String,
    pub index: u64,
    pub size: u64,
    pub blake3: String,
    pub stats_json: String,
    #[serde(skip)]
    pub exr: PathBuf,
    #[serde(skip)]
    pub json: PathBuf,
}

pub struct Outbox {
    dir: PathBuf,
}

fn stem(job: &str, index: u64) -> String {
    // Job ids are [a-z0-9-]; keep anything else out of file names anyway.
    let job: String = job
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("{job}__{index:010}")
}

impl Outbox {
    /// Opens the outbox, removing partial files a killed worker left (an EXR without its JSON
    /// was never finished).
    pub fn open(dir: &Path) -> Result<Outbox> {
        std::fs::create_dir_all(dir).with_context(|| format!("outbox {}", dir.display()))?;
        for e in std::fs::read_dir(dir)?.flatten() {
            let p = e.path();
            let name = p
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or("")
                .to_string();
            let complete_exr = name.ends_with(".exr") && p.with_extension("json").is_file();
            if !(name.ends_with(".json") || complete_exr) {
                let _ = std::fs::remove_file(&p);
            }
        }
        Ok(Outbox {
            dir: dir.to_path_buf(),
        })
    }

    pub fn exr_path(&self, job: &str, index: u64) -> PathBuf {
        self.dir.join(format!("{}.exr", stem(job, index)))
    }

    /// Records a rendered EXR as an entry (hash, size, lease) ready to upload.
    pub fn commit_entry(
        &self,
        exr: &Path,
        worker: &str,
        task: &pb::Task,
        stats_json: &str,
    ) -> Result<OutboxEntry> {
        let bytes = std::fs::read(exr).with_context(|| exr.display().to_string())?;
        let mut entry = OutboxEntry {
            worker_id: worker.to_string(),
            lease_id: task.lease_id.clone(),
            job_id: task.job_id.clone(),
            index: task.index,
            size: bytes.len() as u64,
            blake3: blake3::hash(&bytes).to_hex().to_string(),
            stats_json: stats_json.to_string(),
            exr: exr.to_path_buf(),
            json: exr.with_extension("json"),
        };
        let tmp = exr.with_extension("json.tmp");
        std::fs::write(&tmp, serde_json::to_vec(&entry)?)?;
        std::fs::File::open(&tmp)?.sync_all()?;
        std::fs::rename(&tmp, &entry.json)?;
        if let Ok(d) = std::fs::File::open(&self.dir) {
            let _ = d.sync_all();
        }
        entry.exr = exr.to_path_buf();
        Ok(entry)
    }

    pub fn entries(&self) -> Result<Vec<OutboxEntry>> {
        let mut out = Vec::new();
        for e in std::fs::read_dir(&self.dir)?.flatten() {
            let p = e.path();
            if p.extension().and_then(|x| x.to_str()) != Some("json") {
                continue;
            }
            let text = std::fs::read(&p)?;
            match serde_json::from_slice::<OutboxEntry>(&text) {
                Ok(mut entry) => {
                    entry.exr = p.with_extension("exr");
                    entry.json = p.clone();
                    out.push(entry);
                }
                Err(e) => {
                    tracing::warn!(file = %p.display(), "dropping unreadable outbox entry: {e}");
                    let _ = std::fs::remove_file(&p);
                }
            }
        }
        out.sort_by(|a, b| (&a.job_id, a.index).cmp(&(&b.job_id, b.index)));
        Ok(out)
    }

    fn remove(&self, entry: &OutboxEntry) {
        let _ = std::fs::remove_file(&entry.json);
        let _ = std::fs::remove_file(&entry.exr);
    }

    /// Uploads one entry, waiting out coordinator outages; the entry is removed once the
    /// coordinator has it (committed now or before) or refuses it for good.
    pub async fn upload(&self, client: &Client, entry: &OutboxEntry) -> Result<()> {
        let bytes = std::fs::read(&entry.exr).with_context(|| entry.exr.display().to_string())?;
        let header = pb::UploadHeader {
            worker_id: entry.worker_id.clone(),
            lease_id: entry.lease_id.clone(),
            job_id: entry.job_id.clone(),
            index: entry.index,
            size: entry.size,
            blake3: entry.blake3.clone(),
            stats_json: entry.stats_json.clone(),
        };
        let result = client
            .retry(
                &format!("upload {}#{}", entry.job_id, entry.index),
                false,
                |mut c| {
                    let mut msgs = vec![pb::UploadChunk {
                        kind: Some(pb::upload_chunk::Kind::Header(header.clone())),
                    }];
                    msgs.extend(bytes.chunks(CHUNK).map(|b| pb::UploadChunk {
                        kind: Some(pb::upload_chunk::Kind::Data(b.to_vec())),
                    }));
                    async move {
                        c.upload_sample(tokio_stream::iter(msgs))
                            .await
                            .map(|r| r.into_inner())
                    }
                },
            )
            .await;
        match result {
            Ok(Some(r)) => {
                tracing::info!(job = %entry.job_id, index = entry.index, committed = r.committed, "uploaded");
                self.remove(entry);
                Ok(())
            }
            Ok(None) => Ok(()),
            Err(e) => {
                let code = e.downcast_ref::<tonic::Status>().map(|s| s.code());
                if matches!(
                    code,
                    Some(
                        Code::FailedPrecondition
                            | Code::NotFound
                            | Code::InvalidArgument
                            | Code::DataLoss
                    )
                ) {
                    tracing::warn!(job = %entry.job_id, index = entry.index, "coordinator refused the result, dropping it: {e:#}");
                    self.remove(entry);
                    Ok(())
                } else {
                    Err(e)
                }
            }
        }
    }

    pub async fn flush(&self, client: &Client) -> Result<()> {
        for entry in self.entries()? {
            self.upload(client, &entry).await?;
        }
        Ok(())
    }
}
