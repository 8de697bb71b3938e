//! Prometheus metrics, served as text on `/metrics` by [`serve_metrics`].

use std::sync::Arc;

use prometheus::{Encoder, Histogram, HistogramOpts, IntCounter, IntGauge, Registry, TextEncoder};

use crate::scheduler::Scheduler;

pub struct Metrics {
    pub registry: Registry,
    pub leased: IntCounter,
    /// Starts at the sample index's count when the coordinator opens (see
    /// `Coordinator::open`), so a restart does not reset it and `rate()` sees no reset either.
    pub committed: IntCounter,
    pub duplicate_uploads: IntCounter,
    pub rejected_uploads: IntCounter,
    pub task_failures: IntCounter,
    pub expired_leases: IntCounter,
    pub lease_latency: Histogram,
    queued: IntGauge,
    leased_now: IntGauge,
    done: IntGauge,
    failed: IntGauge,
    samples_per_second: prometheus::Gauge,
}

// Metric names are the constants below; creating or registering them fails only for an
// invalid or duplicate name, a programming error caught by the first test run.
fn counter(registry: &Registry, name: &str, help: &str) -> IntCounter {
    let c = IntCounter::new(name, help).expect("valid static metric name");
    registry
        .register(Box::new(c.clone()))
        .expect("unique metric name");
    c
}

fn gauge(registry: &Registry, name: &str, help: &str) -> IntGauge {
    let g = IntGauge::new(name, help).expect("valid static metric name");
    registry
        .register(Box::new(g.clone()))
        .expect("unique metric name");
    g
}

impl Metrics {
    pub fn new() -> Metrics {
        let registry = Registry::new();
        let lease_latency = Histogram::with_opts(
            HistogramOpts::new("lightfarm_lease_seconds", "LeaseTasks handling time").buckets(
                vec![0.0001, 0.0005, 0.001, 0.005, 0.01, 0.05, 0.1, 0.5, 1.0],
            ),
        )
        .expect("valid static histogram");
        registry
            .register(Box::new(lease_latency.clone()))
            .expect("unique metric name");
        Metrics {
            leased: counter(
                &registry,
                "lightfarm_tasks_leased_total",
                "Tasks handed to workers",
            ),
            committed: counter(
                &registry,
                "lightfarm_samples_committed_total",
                "Samples committed in this data directory, across coordinator restarts",
            ),
            duplicate_uploads: counter(
                &registry,
                "lightfarm_duplicate_uploads_total",
                "Uploads of already committed samples (acknowledged, not stored)",
            ),
            rejected_uploads: counter(
                &registry,
                "lightfarm_rejected_uploads_total",
                "Uploads refused (too large, checksum mismatch)",
            ),
            task_failures: counter(
                &registry,
                "lightfarm_task_failures_total",
                "FailTask reports",
            ),
            expired_leases: counter(
                &registry,
                "lightfarm_expired_leases_total",
                "Leases that ran out and were requeued",
            ),
            lease_latency,
            queued: gauge(
                &registry,
                "lightfarm_tasks_queued",
                "Tasks waiting for a worker",
            ),
            leased_now: gauge(&registry, "lightfarm_tasks_leased", "Tasks being rendered"),
            done: gauge(&registry, "lightfarm_tasks_done", "Tasks committed"),
            failed: gauge(&registry, "lightfarm_tasks_failed", "Tasks failed for good"),
            samples_per_second: {
                let g = prometheus::Gauge::new(
                    "lightfarm_samples_per_second",
                    "Commits per second over the last minute, all jobs",
                )
                .expect("valid static metric name");
                registry
                    .register(Box::new(g.clone()))
                    .expect("unique metric name");
                g
            },
            registry,
        }
    }

    /// The text exposition, gauges refreshed from the scheduler.
    pub fn render(&self, scheduler: &Scheduler) -> String {
        let (q, l, d, f) = scheduler.totals();
        self.queued.set(q as i64);
        self.leased_now.set(l as i64);
        self.done.set(d as i64);
        self.failed.set(f as i64);
        let now = crate::service::now_unix();
        self.samples_per_second.set(
            scheduler
                .jobs(now)
                .iter()
                .map(|j| j.samples_per_second)
                .sum(),
        );
        let mut buf = Vec::new();
        let _ = TextEncoder::new().encode(&self.registry.gather(), &mut buf);
        String::from_utf8_lossy(&buf).into_owned()
    }
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

/// Serves `GET /metrics` on `listener` until `shutdown` resolves, and with `dashboard` the web
/// dashboard's routes ([`crate::Coordinator::dashboard`]) on the same port; over HTTPS with
/// `tls` (the coordinator's certificate and key). The samples/s rate is the derivative of
/// `lightfarm_samples_committed_total` (Prometheus `rate()`).
pub async fn serve_metrics(
    listener: tokio::net::TcpListener,
    metrics: Arc<Metrics>,
    scheduler: Arc<Scheduler>,
    dashboard: Option<axum::Router>,
    tls: Option<tokio_rustls::rustls::ServerConfig>,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let mut app = axum::Router::new().route(
        "/metrics",
        axum::routing::get(move || {
            let (m, s) = (metrics.clone(), scheduler.clone());
            async move { m.render(&s) }
        }),
    );
    if let Some(board) = dashboard {
        app = app.merge(board);
    }
    match tls {
        Some(config) => {
            let listener = crate::tls_listener::TlsListener::new(listener, config)?;
            axum::serve(listener, app)
                .with_graceful_shutdown(shutdown)
                .await
        }
        None => {
            axum::serve(listener, app)
                .with_graceful_shutdown(shutdown)
                .await
        }
    }
}
