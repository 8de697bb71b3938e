//! The render workers in the dashboard: each one's device, state (idle, rendering which
//! sample, draining, stopped, lost), last call, samples rendered and failed, cached heads,
//! and the jobs that blocklisted it. The table is a live fragment.

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::Response;
use maud::{html, Markup};

use super::session::{ApiSession, PageSession};
use super::{html, pages, App};
use crate::scheduler::{WorkerState, WorkerStatus};
use crate::service::now_unix;

fn ago(now: f64, then: Option<f64>) -> String {
    match then {
        None => "not since the coordinator started".into(),
        Some(t) => {
            let s = (now - t).max(0.0);
            if s < 90.0 {
                format!("{s:.0} s ago")
            } else if s < 5400.0 {
                format!("{:.0} min ago", s / 60.0)
            } else {
                format!("{:.1} h ago", s / 3600.0)
            }
        }
    }
}

fn table(workers: &[WorkerStatus], now: f64) -> Markup {
    html! {
        @if workers.is_empty() {
            p { "No worker has registered yet: " code { "lightfarm serve worker --coordinator URL" } }
        } @else {
            div.scroll { table {
                tr {
                    th { "worker" } th { "state" } th.wide { "device" } th { "last call" }
                    th { "rendered" } th { "failed" } th.wide { "cached heads" } th.wide { "blocklisted in" }
                }
                @for w in workers {
                    tr data-worker=(w.name) {
                        td.name { (w.name) }
                        td class=(format!("state-{}", w.state.as_str())) data-field="state" {
                            (w.state.as_str())
                            @if matches!(w.state, WorkerState::Rendering | WorkerState::Draining) {
                                @for (job, index) in &w.rendering {
                                    br; a href=(format!("/jobs/{job}")) { (job) " #" (index) }
                                }
                            }
                        }
                        td.wide.name { (w.device)
                            @if w.memory_bytes > 0 { " · " (w.memory_bytes >> 30) " GiB" } }
                        td { (ago(now, w.last_seen_unix)) }
                        td data-field="rendered" { (w.rendered) }
                        td data-field="failures" { (w.failures) }
                        td.wide.name {
                            (w.cached_heads.len())
                            @if !w.cached_heads.is_empty() { ": " (w.cached_heads.join(", ")) }
                        }
                        td.wide.name {
                            @if w.blocklisted_in.is_empty() { "–" }
                            @for (k, job) in w.blocklisted_in.iter().enumerate() {
                                @if k > 0 { ", " }
                                a href=(format!("/jobs/{job}")) { (job) }
                            }
                        }
                    }
                }
            } }
        }
    }
}

/// `GET /workers`.
pub(super) async fn page(State(app): State<App>, PageSession(s): PageSession) -> Response {
    let now = now_unix();
    let body = html! {
        h1 { "Workers" }
        p { small { "Lost: silent for longer than a lease ("
            (format!("{:.0}", app.scheduler.lease_seconds())) " s); its tasks go back to the queue." } }
        div data-live="/workers/table" { (table(&app.scheduler.workers(now), now)) }
    };
    html(StatusCode::OK, pages::layout("Workers", &s.csrf, body))
}

/// `GET /workers/table`: the table alone, for the live refresh.
pub(super) async fn fragment(State(app): State<App>, _: ApiSession) -> Response {
    let now = now_unix();
    html(StatusCode::OK, table(&app.scheduler.workers(now), now))
}
