//! Group commit: one file-system sync and one sled flush for every upload that arrived while
//! the previous one ran.
//!
//! Acknowledging an upload requires its blob and its index entry on disk. Syncing per upload
//! costs an fsync pair each (≈1,700 uploads/s here), and concurrent `sled::Db::flush_async`
//! calls were seen to deadlock inside sled 0.34; a single flusher task that serves waiters in
//! batches avoids both. Blobs are synced before the index, so an index entry never survives a
//! power cut that its blob did not.

use std::sync::Arc;
use std::time::Duration;

use lightfarm_store::BlobStore;
use tokio::sync::{mpsc, oneshot};

type Waiter = oneshot::Sender<Result<(), String>>;

/// How long the first waiter of a batch waits for others; small next to a render (seconds)
/// and to an upload's transfer.
const COMMIT_WINDOW: Duration = Duration::from_millis(2);

#[derive(Clone)]
pub struct GroupSync {
    tx: mpsc::UnboundedSender<Waiter>,
}

impl GroupSync {
    /// A handle and the receiving end to pass to [`GroupSync::run`].
    pub fn channel() -> (GroupSync, mpsc::UnboundedReceiver<Waiter>) {
        let (tx, rx) = mpsc::unbounded_channel();
        (GroupSync { tx }, rx)
    }

    /// Serves sync requests until every handle is gone; also syncs once a second so leases
    /// and heartbeats reach the disk without an upload.
    pub async fn run(
        mut rx: mpsc::UnboundedReceiver<Waiter>,
        db: sled::Db,
        blobs: Arc<dyn BlobStore>,
    ) {
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        loop {
            let mut waiters: Vec<Waiter> = Vec::new();
            tokio::select! {
                w = rx.recv() => match w {
                    Some(w) => waiters.push(w),
                    None => return,
                },
                _ = tick.tick() => {}
            }
            if !waiters.is_empty() {
                // A short window gathers the uploads finishing together into one sync.
                tokio::time::sleep(COMMIT_WINDOW).await;
            }
            while let Ok(w) = rx.try_recv() {
                waiters.push(w);
            }
            let (db, blobs) = (db.clone(), blobs.clone());
            let result = tokio::task::spawn_blocking(move || {
                blobs.sync().map_err(|e| e.to_string())?;
                db.flush().map(|_| ()).map_err(|e| e.to_string())
            })
            .await
            .unwrap_or_else(|e| Err(format!("sync thread: {e}")));
            if let Err(e) = &result {
                tracing::error!("syncing the data directory: {e}");
            }
            for w in waiters {
                let _ = w.send(result.clone());
            }
        }
    }

    /// Waits until everything written before this call is durable.
    pub async fn sync(&self) -> Result<(), String> {
        let (tx, rx) = oneshot::channel();
        self.tx
            .send(tx)
            .map_err(|_| "the coordinator is shutting down".to_string())?;
        rx.await
            .map_err(|_| "the coordinator is shutting down".to_string())?
    }
}
