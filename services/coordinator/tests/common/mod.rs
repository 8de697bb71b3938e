//! What the coordinator's test files share: a coordinator serving gRPC and its dashboard, and
//! a headless browser.
// Each test file uses a part of this module.
#![allow(dead_code)]

pub mod browser;

use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;

use lightfarm_coordinator::dashboard::DashboardConfig;
use lightfarm_coordinator::scheduler::Scheduler;
use lightfarm_coordinator::{Coordinator, CoordinatorConfig};
use lightfarm_scene::Catalog;

/// A coordinator serving until the runtime ends.
pub struct Served {
    pub scheduler: Arc<Scheduler>,
    /// The metrics port: /metrics and the dashboard (plain HTTP, plain-HTTP cookies).
    pub web: SocketAddr,
    /// The gRPC API, as a worker's `--coordinator`.
    pub grpc: String,
}

/// A coordinator with its data under `dir` (logged into with `token`), its gRPC API and its
/// metrics port with the dashboard on ephemeral local ports.
pub async fn serve_dashboard(dir: &Path, token: &str) -> Served {
    let config = CoordinatorConfig::new(
        dir.join("data"),
        token.into(),
        Catalog::builtin().expect("catalog"),
    );
    let coordinator = tokio::task::spawn_blocking(move || Coordinator::open(config))
        .await
        .expect("join")
        .expect("open");
    let bind = || tokio::net::TcpListener::bind("127.0.0.1:0");
    let (web, grpc) = (bind().await.expect("bind"), bind().await.expect("bind"));
    let served = Served {
        scheduler: coordinator.scheduler().clone(),
        web: web.local_addr().expect("addr"),
        grpc: format!("http://{}", grpc.local_addr().expect("addr")),
    };
    let board = coordinator
        .dashboard(&DashboardConfig {
            token: token.into(),
            secure_cookies: false,
            trainer: None,
        })
        .expect("dashboard");
    tokio::spawn(lightfarm_coordinator::metrics::serve_metrics(
        web,
        coordinator.metrics().clone(),
        coordinator.scheduler().clone(),
        Some(board),
        None,
        std::future::pending(),
    ));
    tokio::spawn(coordinator.serve(grpc, std::future::pending()));
    served
}
