//! What the coordinator's test files share: a coordinator serving its dashboard, and a
//! headless browser.
// Each test file uses a part of this module.
#![allow(dead_code)]

pub mod browser;

use std::net::SocketAddr;
use std::path::Path;

use lightfarm_coordinator::dashboard::DashboardConfig;
use lightfarm_coordinator::{Coordinator, CoordinatorConfig};
use lightfarm_scene::Catalog;

/// A coordinator with its data under `dir`, its metrics port and dashboard (logged into with
/// `token`, plain-HTTP cookies) served on an ephemeral local port until the runtime ends.
pub async fn serve_dashboard(dir: &Path, token: &str) -> (Coordinator, SocketAddr) {
    let config = CoordinatorConfig::new(
        dir.join("data"),
        token.into(),
        Catalog::builtin().expect("catalog"),
    );
    let coordinator = tokio::task::spawn_blocking(move || Coordinator::open(config))
        .await
        .expect("join")
        .expect("open");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("addr");
    tokio::spawn(lightfarm_coordinator::metrics::serve_metrics(
        listener,
        coordinator.metrics().clone(),
        coordinator.scheduler().clone(),
        Some(DashboardConfig {
            token: token.into(),
            secure_cookies: false,
        }),
        std::future::pending(),
    ));
    (coordinator, addr)
}
