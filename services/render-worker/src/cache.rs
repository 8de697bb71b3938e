//! Content-addressed asset cache: `assets/blobs/<blake3>`, verified on arrival, plus per-catalog
//! directories that map the catalog's relative paths onto those blobs.

use std::collections::HashSet;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use lightfarm_proto::v1 as pb;
use lightfarm_scene::Catalog;
use tokio::sync::Mutex;

use crate::client::Client;

pub struct AssetCache {
    root: PathBuf,
    /// One fetch at a time: two tasks needing the same asset must not race on its file.
    fetching: Mutex<()>,
}

fn valid_hash(h: &str) -> bool {
    h.len() == 64
        && h.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

impl AssetCache {
    pub fn open(root: &Path) -> Result<AssetCache> {
        std::fs::create_dir_all(root.join("blobs"))
            .with_context(|| format!("asset cache {}", root.display()))?;
        std::fs::create_dir_all(root.join("tmp"))?;
        // Partial downloads of a killed worker.
        for e in std::fs::read_dir(root.join("tmp"))?.flatten() {
            let _ = std::fs::remove_file(e.path());
        }
        Ok(AssetCache {
            root: root.to_path_buf(),
            fetching: Mutex::new(()),
        })
    }

    fn blob(&self, hash: &str) -> PathBuf {
        self.root.join("blobs").join(hash)
    }

    /// Hashes of every cached blob (sent to the coordinator for locality).
    pub fn hashes(&self) -> Result<Vec<String>> {
        let mut v = Vec::new();
        for e in std::fs::read_dir(self.root.join("blobs"))?.flatten() {
            if let Some(name) = e.file_name().to_str() {
                if valid_hash(name) {
                    v.push(name.to_string());
                }
            }
        }
        v.sort();
        Ok(v)
    }

    /// Fetches `hash` unless cached; the bytes are verified before they enter the cache.
    pub async fn ensure(&self, client: &Client, hash: &str) -> Result<PathBuf> {
        if !valid_hash(hash) {
            bail!("asset hash `{hash}` from the coordinator is not a BLAKE3 hex digest");
        }
        let path = self.blob(hash);
        if path.is_file() {
            return Ok(path);
        }
        let _guard = self.fetching.lock().await;
        if path.is_file() {
            return Ok(path);
        }
        let tmp = self.root.join("tmp").join(format!("{hash}.part"));
        let req = pb::FetchAssetRequest {
            blake3: hash.to_string(),
        };
        let bytes = client
            .retry(&format!("fetch asset {hash}"), false, |mut c| {
                let req = req.clone();
                async move {
                    let mut stream = c.fetch_asset(req).await?.into_inner();
                    let mut buf = Vec::new();
                    while let Some(chunk) = stream.message().await? {
                        buf.extend_from_slice(&chunk.data);
                    }
                    Ok(buf)
                }
            })
            .await?
            .context("fetch stopped")?;
        let got = blake3::hash(&bytes).to_hex().to_string();
        if got != hash {
            bail!(
                "asset {hash} arrived with blake3 {got} ({} bytes): corrupt transfer",
                bytes.len()
            );
        }
        let mut f = std::fs::File::create(&tmp).with_context(|| tmp.display().to_string())?;
        f.write_all(&bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)?;
        tracing::info!(asset = hash, bytes = bytes.len(), "asset cached");
        Ok(path)
    }

    /// A directory holding the catalog file and links from the given assets' catalog paths to
    /// their cached blobs, loaded as a [`Catalog`] (ids resolve to files, hashes are checked).
    pub fn materialize_catalog(
        &self,
        catalog_hash: &str,
        assets: &[pb::AssetRef],
    ) -> Result<Catalog> {
        let dir = self.root.join("catalogs").join(catalog_hash);
        std::fs::create_dir_all(&dir)?;
        let file = dir.join(lightfarm_scene::catalog::CATALOG_FILE);
        if !file.is_file() {
            link(&self.blob(catalog_hash), &file)?;
        }
        let catalog = Catalog::load(&file)?;
        let wanted: HashSet<&str> = assets.iter().map(|a| a.blake3.as_str()).collect();
        for asset in catalog
            .assets
            .iter()
            .filter(|a| wanted.contains(a.blake3.as_str()))
        {
            let target = catalog.path_of(asset);
            if !target.exists() {
                if let Some(parent) = target.parent() {
                    std::fs::create_dir_all(parent)?;
                }
                link(&self.blob(&asset.blake3), &target)?;
            }
        }
        Ok(catalog)
    }
}

/// Hard link (same file system, no copy), falling back to a copy.
fn link(from: &Path, to: &Path) -> Result<()> {
    if std::fs::hard_link(from, to).is_err() {
        let tmp = to.with_extension("part");
        std::fs::copy(from, &tmp)
            .with_context(|| format!("{} -> {}", from.display(), tmp.display()))?;
        std::fs::rename(&tmp, to)?;
    }
    Ok(())
}
