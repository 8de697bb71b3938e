//! The worker's side of the `Workers` API: bearer token on every call, retries with backoff
//! while the coordinator is unreachable (a restart, an outage), clear errors otherwise.

use std::path::Path;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use lightfarm_proto::v1 as pb;
use lightfarm_proto::v1::workers_client::WorkersClient;
use tokio::sync::watch;
use tonic::{Code, Status};

pub use lightfarm_proto::client::{channel, transient, Auth, AuthedChannel};

pub type Workers = WorkersClient<AuthedChannel>;

#[derive(Clone)]
pub struct Client {
    inner: Workers,
    stop: watch::Receiver<bool>,
}

impl Client {
    pub async fn connect(
        url: &str,
        token: &str,
        tls_ca: Option<&Path>,
        stop: watch::Receiver<bool>,
    ) -> Result<Client> {
        let (ch, auth) = channel(url, token, tls_ca)?;
        Ok(Client {
            inner: WorkersClient::with_interceptor(ch, auth).max_decoding_message_size(64 << 20),
            stop,
        })
    }

    pub fn raw(&self) -> Workers {
        self.inner.clone()
    }

    /// Runs `f` until it succeeds or fails for a non-transient reason. While the coordinator
    /// is unreachable, waits with backoff (up to 5 s); with `until_stop`, gives up on shutdown.
    pub async fn retry<T, F, Fut>(
        &self,
        what: &str,
        until_stop: bool,
        mut f: F,
    ) -> Result<Option<T>>
    where
        F: FnMut(Workers) -> Fut,
        Fut: std::future::Future<Output = Result<T, Status>>,
    {
        let mut wait = Duration::from_millis(250);
        let mut warned = false;
        loop {
            match f(self.inner.clone()).await {
                Ok(v) => {
                    if warned {
                        tracing::info!("coordinator reachable again ({what})");
                    }
                    return Ok(Some(v));
                }
                Err(s) if s.code() == Code::Unauthenticated => {
                    bail!(
                        "the coordinator refused this worker's token: {}",
                        s.message()
                    )
                }
                Err(s) if transient(&s) => {
                    if !warned {
                        tracing::warn!(
                            "{what}: coordinator unreachable ({}); retrying",
                            s.message()
                        );
                        warned = true;
                    }
                    if until_stop && *self.stop.borrow() {
                        return Ok(None);
                    }
                    let mut stop = self.stop.clone();
                    let _ = tokio::time::timeout(wait, stop.changed()).await;
                    wait = (wait * 2).min(Duration::from_secs(5));
                }
                Err(s) => return Err(anyhow::Error::new(s).context(what.to_string())),
            }
        }
    }

    pub async fn register(
        &self,
        name: &str,
        device: &str,
        cached: Vec<String>,
    ) -> Result<pb::RegisterWorkerResponse> {
        let req = pb::RegisterWorkerRequest {
            name: name.to_string(),
            device: device.to_string(),
            memory_bytes: 0,
            cached_assets: cached,
        };
        self.retry("register", false, |mut c| {
            let req = req.clone();
            async move { c.register_worker(req).await.map(|r| r.into_inner()) }
        })
        .await?
        .context("register: stopped")
    }

    /// Leases up to `capacity` tasks; empty on shutdown while the coordinator is away.
    pub async fn lease(
        &self,
        worker: &str,
        capacity: u32,
        cached: Vec<String>,
    ) -> Result<Vec<pb::Task>> {
        let req = pb::LeaseTasksRequest {
            worker_id: worker.to_string(),
            capacity,
            cached_assets: cached,
        };
        Ok(self
            .retry("lease", true, |mut c| {
                let req = req.clone();
                async move { c.lease_tasks(req).await.map(|r| r.into_inner().tasks) }
            })
            .await?
            .unwrap_or_default())
    }

    /// One heartbeat (no retry: the next one follows soon); returns the lost leases. After a
    /// shutdown request it says the worker is draining.
    pub async fn heartbeat(&self, worker: &str, leases: &[String]) -> Result<Vec<String>> {
        let req = pb::HeartbeatRequest {
            draining: *self.stop.borrow(),
            worker_id: worker.to_string(),
            leases: leases
                .iter()
                .map(|l| pb::LeaseProgress {
                    lease_id: l.clone(),
                    progress: 0.0,
                })
                .collect(),
        };
        Ok(self
            .inner
            .clone()
            .heartbeat(req)
            .await?
            .into_inner()
            .lost_leases)
    }

    /// Tells the coordinator this worker is leaving (best effort: it is going either way).
    pub async fn leaving(&self, worker: &str) {
        let req = pb::HeartbeatRequest {
            worker_id: worker.to_string(),
            leases: Vec::new(),
            draining: true,
        };
        if let Err(e) = self.inner.clone().heartbeat(req).await {
            tracing::debug!("saying goodbye to the coordinator: {e}");
        }
    }

    pub async fn fail(&self, worker: &str, lease: &str, reason: &str) -> Result<bool> {
        let req = pb::FailTaskRequest {
            worker_id: worker.to_string(),
            lease_id: lease.to_string(),
            reason: reason.to_string(),
        };
        Ok(self
            .retry("fail task", true, |mut c| {
                let req = req.clone();
                async move { c.fail_task(req).await.map(|r| r.into_inner().will_retry) }
            })
            .await?
            .unwrap_or(false))
    }
}
