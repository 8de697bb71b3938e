//! The farm's web dashboard, served by the coordinator on its metrics port next to `/metrics`
//! (which keeps its own rule: open, for Prometheus on the operator's network). Everything else
//! needs a session bought with the coordinator's token on `/login` ([`session`]); a change
//! (pause, resume, cancel, priority) is a POST carrying the session's CSRF token.
//!
//! Pages: `/` the jobs (state, progress, counts, samples/s, ETA, priority, actions), `/jobs/ID`
//! one job (the same, its spec as submitted, failures with every reason and worker, the
//! blocklist, a paginated gallery of its committed samples, [`gallery`]), `/jobs/ID/samples/N`
//! one sample's passes, metadata and EXR, `/workers` the render workers ([`workers_page`]),
//! `/trainer` the trainer service's jobs, loss curves and validation relights
//! ([`trainer_page`]).
//! `/api/jobs` is the JSON the pages poll every two seconds to stay current; parts of pages
//! marked `data-live` are re-fetched as server-rendered fragments.

mod gallery;
mod pages;
pub mod preview;
mod session;
mod trainer_page;
mod workers_page;

use std::sync::Arc;

use axum::extract::{Form, Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use axum::Router;
use serde::{Deserialize, Serialize};

use crate::error::CoordError;
use crate::scheduler::{RunState, Scheduler};
use crate::service::now_unix;
use preview::Previews;
pub use session::COOKIE;
use session::{ApiSession, Login, PageSession, Session, Sessions};
use trainer_page::Trainer;
pub use trainer_page::TrainerLink;

/// How the dashboard authenticates: the coordinator's bearer token, and whether its cookies
/// must be TLS-only (they must when the coordinator serves TLS).
#[derive(Clone, Debug)]
pub struct DashboardConfig {
    pub token: String,
    pub secure_cookies: bool,
    /// The trainer service whose jobs the dashboard shows, if any.
    pub trainer: Option<TrainerLink>,
}

#[derive(Clone)]
struct App {
    scheduler: Arc<Scheduler>,
    sessions: Arc<Sessions>,
    previews: Previews,
    trainer: Option<Trainer>,
}

/// The dashboard's routes, to be merged into the metrics server's router; `previews` makes
/// and caches the gallery's images. Fails only on a trainer address that is no URL.
pub fn router(
    scheduler: Arc<Scheduler>,
    previews: Previews,
    cfg: &DashboardConfig,
) -> Result<Router, CoordError> {
    let trainer = cfg
        .trainer
        .as_ref()
        .map(Trainer::connect)
        .transpose()
        .map_err(CoordError::Invalid)?;
    let app = App {
        scheduler,
        sessions: Arc::new(Sessions::new(&cfg.token, cfg.secure_cookies)),
        previews,
        trainer,
    };
    Ok(Router::new()
        .route("/", get(jobs_page))
        .route("/login", get(login_page).post(login))
        .route("/logout", post(logout))
        .route("/jobs/{id}", get(job_page))
        .route("/jobs/{id}/{action}", post(job_action))
        .route("/jobs/{id}/gallery", get(gallery::fragment))
        .route("/jobs/{id}/samples/{index}", get(gallery::sample_page))
        .route(
            "/jobs/{id}/samples/{index}/{file}",
            get(gallery::sample_file),
        )
        .route("/workers", get(workers_page::page))
        .route("/workers/table", get(workers_page::fragment))
        .route("/trainer", get(trainer_page::page))
        .route("/trainer/table", get(trainer_page::fragment))
        .route("/trainer/{id}", get(trainer_page::job_page))
        .route("/trainer/{id}/losses", get(trainer_page::losses))
        .route(
            "/trainer/{id}/relit/{job}/{index}",
            get(trainer_page::relit),
        )
        .route("/api/jobs", get(jobs_json))
        .with_state(app))
}

fn html(status: StatusCode, markup: maud::Markup) -> Response {
    (
        status,
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        markup.into_string(),
    )
        .into_response()
}

fn to_login() -> Response {
    Redirect::to("/login").into_response()
}

async fn login_page(State(app): State<App>, headers: HeaderMap) -> Response {
    if app.sessions.get(&headers).is_some() {
        return Redirect::to("/").into_response();
    }
    html(StatusCode::OK, pages::login(None))
}

#[derive(Deserialize)]
struct LoginForm {
    token: String,
}

async fn login(State(app): State<App>, Form(f): Form<LoginForm>) -> Response {
    match app.sessions.login(&f.token) {
        Login::Right => {}
        Login::Wrong => {
            tracing::warn!("dashboard: a login with a wrong token");
            return html(
                StatusCode::UNAUTHORIZED,
                pages::login(Some("That is not this coordinator's token.")),
            );
        }
        Login::Paused(wait) => {
            tracing::warn!("dashboard: logins paused after repeated wrong tokens");
            return html(
                StatusCode::TOO_MANY_REQUESTS,
                pages::login(Some(&format!(
                    "Too many wrong tokens in the last minute; try again in {wait} s."
                ))),
            );
        }
    }
    match app.sessions.open() {
        Some((_, cookie)) => ([(header::SET_COOKIE, cookie)], Redirect::to("/")).into_response(),
        None => html(
            StatusCode::INTERNAL_SERVER_ERROR,
            pages::error(
                "Cannot log in",
                "the system has no randomness for a session id",
                None,
            ),
        ),
    }
}

#[derive(Deserialize)]
struct ActionForm {
    csrf: String,
    #[serde(default)]
    priority: Option<String>,
}

async fn logout(State(app): State<App>, headers: HeaderMap, Form(f): Form<ActionForm>) -> Response {
    match app.sessions.get(&headers) {
        Some(s) if s.csrf_matches(&f.csrf) => {
            let cookie = app.sessions.close(&headers);
            ([(header::SET_COOKIE, cookie)], Redirect::to("/login")).into_response()
        }
        _ => to_login(),
    }
}

async fn jobs_page(State(app): State<App>, PageSession(s): PageSession) -> Response {
    html(
        StatusCode::OK,
        pages::jobs(&app.scheduler.jobs(now_unix()), &s.csrf),
    )
}

fn coord_error(e: &CoordError, s: &Session) -> Response {
    let status = match e {
        CoordError::UnknownJob(_) | CoordError::NotFound(_) => StatusCode::NOT_FOUND,
        CoordError::Conflict(_) | CoordError::Invalid(_) => StatusCode::CONFLICT,
        _ => StatusCode::INTERNAL_SERVER_ERROR,
    };
    html(
        status,
        pages::error(
            status.canonical_reason().unwrap_or("Error"),
            &e.to_string(),
            Some(&s.csrf),
        ),
    )
}

async fn job_page(
    State(app): State<App>,
    PageSession(s): PageSession,
    Path(id): Path<String>,
    Query(q): Query<gallery::PageQuery>,
) -> Response {
    let job = app.scheduler.job(&id, now_unix());
    let shown = job.and_then(|j| Ok((gallery::section(&app, &id, q.page)?, j)));
    match shown {
        Ok((samples, j)) => html(StatusCode::OK, pages::job(&j, samples, &s.csrf)),
        Err(e) => coord_error(&e, &s),
    }
}

async fn job_action(
    State(app): State<App>,
    PageSession(s): PageSession,
    Path((id, action)): Path<(String, String)>,
    Form(f): Form<ActionForm>,
) -> Response {
    if !s.csrf_matches(&f.csrf) {
        return html(
            StatusCode::FORBIDDEN,
            pages::error(
                "Forbidden",
                "the form's CSRF token is not this session's; reload the page",
                Some(&s.csrf),
            ),
        );
    }
    let now = now_unix();
    let done = match action.as_str() {
        "pause" => app.scheduler.set_run_state(&id, RunState::Paused, now),
        "resume" => app.scheduler.set_run_state(&id, RunState::Running, now),
        "cancel" => app.scheduler.set_run_state(&id, RunState::Cancelled, now),
        "priority" => match f.priority.as_deref().map(str::trim).map(str::parse::<i32>) {
            Some(Ok(p)) => app.scheduler.set_priority(&id, p, now),
            _ => Err(CoordError::Invalid(format!(
                "priority '{}' is not a whole number",
                f.priority.unwrap_or_default()
            ))),
        },
        other => Err(CoordError::Invalid(format!(
            "'{other}' is not an action (pause, resume, cancel, priority)"
        ))),
    };
    match done {
        Ok(_) => {
            tracing::info!(job = %id, action = %action, "dashboard action");
            Redirect::to(&format!("/jobs/{id}")).into_response()
        }
        Err(e) => coord_error(&e, &s),
    }
}

/// One job as the pages' refresh script reads it: the cells' text, ready to show.
#[derive(Serialize)]
struct JobRow {
    id: String,
    state: &'static str,
    count: u64,
    done: u64,
    leased: u64,
    queued: u64,
    failed: u64,
    rate: String,
    eta: String,
    priority: i32,
}

async fn jobs_json(State(app): State<App>, _: ApiSession) -> Response {
    let rows: Vec<JobRow> = app
        .scheduler
        .jobs(now_unix())
        .iter()
        .map(|j| JobRow {
            id: j.record.id.clone(),
            state: pages::state(j),
            count: j.record.count,
            done: j.done,
            leased: j.leased,
            queued: j.queued,
            failed: j.failed,
            rate: pages::rate(j),
            eta: pages::eta(j),
            priority: j.record.priority,
        })
        .collect();
    axum::Json(rows).into_response()
}
