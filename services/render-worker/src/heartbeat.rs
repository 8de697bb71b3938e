//! The worker's heartbeat: one task that keeps every lease the worker holds alive (the sample
//! being rendered and the next one being prepared) and tells the coordinator at once when a
//! shutdown request makes the worker drain.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::client::Client;

/// The leases a worker holds, shared with its heartbeat.
#[derive(Clone, Default)]
pub(crate) struct HeldLeases(Arc<Mutex<Vec<String>>>);

impl HeldLeases {
    fn lock(&self) -> MutexGuard<'_, Vec<String>> {
        // A panic elsewhere cannot leave the list half-written: every update is one push or
        // one retain.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub(crate) fn add(&self, lease: &str) {
        self.lock().push(lease.to_string());
    }

    pub(crate) fn remove(&self, lease: &str) {
        self.lock().retain(|l| l != lease);
    }

    pub(crate) fn list(&self) -> Vec<String> {
        self.lock().clone()
    }
}

/// A running heartbeat; [`Heartbeat::end`] stops it.
pub(crate) struct Heartbeat {
    end: watch::Sender<bool>,
    task: JoinHandle<()>,
}

impl Heartbeat {
    /// Heartbeats `held` every `every` while it is not empty, and once more at once when `stop`
    /// turns true (the heartbeat then says the worker is draining).
    pub(crate) fn start(
        client: Client,
        worker: String,
        held: HeldLeases,
        every: Duration,
        mut stop: watch::Receiver<bool>,
    ) -> Heartbeat {
        let (end, mut end_rx) = watch::channel(false);
        let task = tokio::spawn(async move {
            let mut draining = *stop.borrow();
            loop {
                tokio::select! {
                    _ = tokio::time::sleep(every) => {}
                    _ = end_rx.changed() => return,
                    _ = stop.changed(), if !draining => draining = true,
                }
                let leases = held.list();
                if leases.is_empty() {
                    continue;
                }
                match client.heartbeat(&worker, &leases).await {
                    Ok(lost) => {
                        for lease in lost.iter().filter(|l| leases.contains(l)) {
                            tracing::warn!(lease = %lease, "lease lost while held; the result will be offered anyway");
                        }
                    }
                    Err(e) => tracing::warn!("heartbeat: {e:#}"),
                }
            }
        });
        Heartbeat { end, task }
    }

    pub(crate) async fn end(self) {
        let _ = self.end.send(true);
        let _ = self.task.await;
    }
}
