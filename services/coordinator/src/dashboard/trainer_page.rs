//! The trainer in the dashboard, when the coordinator knows one (`--trainer URL`): its jobs,
//! each job's loss curves drawn as inline SVG, and validation images — committed samples (the
//! test split first) relit by the job's newest checkpoint under their *other* lighting, shown
//! between the input (lit0) and the ground truth the renderer made for that lighting (lit1).

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::{Path, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use lightfarm_proto::client::AuthedChannel;
use lightfarm_proto::v1 as pb;
use lightfarm_store::SampleRecord;
use maud::{html, Markup};

use super::session::{ApiSession, PageSession};
use super::{html, pages, App};

/// Calls that render a page wait this long for the trainer.
const CALL: Duration = Duration::from_secs(5);
/// A relight runs the network on the trainer's device: on a CPU that takes a while.
const RELIGHT: Duration = Duration::from_secs(300);
/// Samples relit per job page.
const VALIDATION_SAMPLES: usize = 3;
/// Relit images kept in memory (a few hundred KB each at most).
const CACHED_RELIGHTS: usize = 64;

/// Where the trainer service is and how to reach it.
#[derive(Clone, Debug)]
pub struct TrainerLink {
    pub url: String,
    pub token: String,
    /// CA certificate (PEM) of a TLS trainer.
    pub tls_ca: Option<PathBuf>,
}

type Client = pb::trainer_client::TrainerClient<AuthedChannel>;
/// (train job, checkpoint step, sample job, index): one relit validation image.
type RelitKey = (String, u64, String, u64);

/// A connection to the trainer and the relit images made so far.
#[derive(Clone)]
pub struct Trainer {
    url: String,
    client: Client,
    /// Relit PNGs made so far.
    relit: Arc<Mutex<HashMap<RelitKey, Arc<Vec<u8>>>>>,
}

impl Trainer {
    /// Connects lazily: a trainer that is down shows as such on the page, not at start.
    pub fn connect(link: &TrainerLink) -> Result<Trainer, String> {
        let (ch, auth) =
            lightfarm_proto::client::channel(&link.url, &link.token, link.tls_ca.as_deref())
                .map_err(|e| format!("--trainer {}: {e}", link.url))?;
        let client = pb::trainer_client::TrainerClient::with_interceptor(ch, auth)
            .max_decoding_message_size(64 << 20)
            .max_encoding_message_size(256 << 20);
        Ok(Trainer {
            url: link.url.clone(),
            client,
            relit: Arc::new(Mutex::new(HashMap::new())),
        })
    }

    fn unreachable(&self, e: impl std::fmt::Display) -> String {
        format!("the trainer at {} did not answer: {e}", self.url)
    }

    async fn jobs(&self) -> Result<Vec<pb::TrainJob>, String> {
        let mut client = self.client.clone();
        let call = client.list_train_jobs(pb::ListTrainJobsRequest {});
        match tokio::time::timeout(CALL, call).await {
            Ok(Ok(r)) => Ok(r.into_inner().jobs),
            Ok(Err(s)) => Err(self.unreachable(s.message())),
            Err(_) => Err(self.unreachable("no reply within 5 s")),
        }
    }

    /// The job and its whole loss curve (the first message of its watch stream).
    async fn progress(&self, id: &str) -> Result<pb::TrainProgress, String> {
        let job = pb::TrainJobRef {
            job_id: id.to_owned(),
        };
        let mut client = self.client.clone();
        let first = async move {
            let mut stream = client.watch_train_job(job).await?.into_inner();
            stream.message().await
        };
        match tokio::time::timeout(CALL, first).await {
            Ok(Ok(Some(p))) => Ok(p),
            Ok(Ok(None)) => Err(self.unreachable("the watch stream ended at once")),
            Ok(Err(s)) if s.code() == tonic::Code::NotFound => Err(s.message().to_owned()),
            Ok(Err(s)) => Err(self.unreachable(s.message())),
            Err(_) => Err(self.unreachable("no reply within 5 s")),
        }
    }

    async fn latest_checkpoint(&self, id: &str) -> Result<Option<u64>, String> {
        let mut client = self.client.clone();
        let call = client.list_checkpoints(pb::TrainJobRef {
            job_id: id.to_owned(),
        });
        match tokio::time::timeout(CALL, call).await {
            Ok(Ok(r)) => Ok(r
                .into_inner()
                .checkpoints
                .iter()
                .find(|c| c.latest)
                .map(|c| c.step)),
            Ok(Err(s)) if s.code() == tonic::Code::NotFound => Err(s.message().to_owned()),
            Ok(Err(s)) => Err(self.unreachable(s.message())),
            Err(_) => Err(self.unreachable("no reply within 5 s")),
        }
    }
}

fn state_name(s: i32) -> &'static str {
    match pb::TrainJobState::try_from(s).unwrap_or(pb::TrainJobState::Unspecified) {
        pb::TrainJobState::Queued => "queued",
        pb::TrainJobState::Running => "running",
        pb::TrainJobState::Completed => "completed",
        pb::TrainJobState::Failed => "failed",
        pb::TrainJobState::Cancelled => "cancelled",
        pb::TrainJobState::Unspecified => "unknown",
    }
}

fn kind_name(k: i32) -> &'static str {
    match pb::TrainJobKind::try_from(k).unwrap_or(pb::TrainJobKind::Unspecified) {
        pb::TrainJobKind::Adapt => "adapt",
        _ => "train",
    }
}

fn no_trainer() -> Markup {
    html! {
        p { "No trainer is configured: start the coordinator with "
            code { "--trainer http://HOST:7071" } " (and " code { "--trainer-token" }
            " when its token differs)." }
    }
}

fn jobs_table(jobs: &[pb::TrainJob]) -> Markup {
    html! {
        @if jobs.is_empty() {
            p { "No train jobs yet: " code { "lightfarm train train.toml --trainer URL" } }
        } @else {
            div.scroll { table {
                tr { th { "job" } th { "kind" } th { "state" } th { "progress" } th.wide { "dataset" } th { "error" } }
                @for j in jobs {
                    tr data-train-job=(j.id) {
                        td { a href=(format!("/trainer/{}", j.id)) { (j.id) } }
                        td { (kind_name(j.kind)) }
                        td data-field="state" { (state_name(j.state)) }
                        td { progress max=(j.steps.max(1)) value=(j.step) {} " " (j.step) " / " (j.steps) }
                        td.wide.name { (j.dataset) }
                        td.reason { (j.error) }
                    }
                }
            } }
        }
    }
}

async fn table(app: &App) -> Markup {
    match &app.trainer {
        None => no_trainer(),
        Some(t) => match t.jobs().await {
            Ok(jobs) => jobs_table(&jobs),
            Err(e) => html! { p.err { (e) } },
        },
    }
}

/// `GET /trainer`.
pub(super) async fn page(State(app): State<App>, PageSession(s): PageSession) -> Response {
    let body = html! {
        h1 { "Trainer" }
        div data-live="/trainer/table" { (table(&app).await) }
    };
    html(StatusCode::OK, pages::layout("Trainer", &s.csrf, body))
}

/// `GET /trainer/table`: the jobs table alone, for the live refresh.
pub(super) async fn fragment(State(app): State<App>, _: ApiSession) -> Response {
    html(StatusCode::OK, table(&app).await)
}

/// The loss terms drawn, with their colours; all-zero terms are left out.
const TERMS: [(&str, &str); 9] = [
    ("total", "#222"),
    ("relit", "#d62728"),
    ("normal", "#1f77b4"),
    ("normal_lens", "#17becf"),
    ("albedo", "#ff7f0e"),
    ("residual", "#9467bd"),
    ("perceptual", "#2ca02c"),
    ("adversarial", "#8c564b"),
    ("identity", "#e377c2"),
];

fn term(p: &pb::LossPoint, name: &str) -> f32 {
    match name {
        "total" => p.total,
        "relit" => p.relit,
        "normal" => p.normal,
        "normal_lens" => p.normal_lens,
        "albedo" => p.albedo,
        "residual" => p.residual,
        "perceptual" => p.perceptual,
        "adversarial" => p.adversarial,
        "identity" => p.identity,
        _ => 0.0,
    }
}

/// The loss curves on a log scale, at most ~500 points per curve whatever the job's length.
pub(super) fn loss_plot(points: &[pb::LossPoint]) -> Markup {
    let (w, h, left, bottom) = (800.0f64, 300.0f64, 50.0f64, 24.0f64);
    let stride = points.len().div_ceil(500).max(1);
    let shown: Vec<&pb::LossPoint> = points
        .iter()
        .enumerate()
        .filter(|(i, _)| i % stride == 0 || *i + 1 == points.len())
        .map(|(_, p)| p)
        .collect();
    let positive = |v: f32| v.is_finite() && v > 0.0;
    let series: Vec<(&str, &str)> = TERMS
        .iter()
        .copied()
        .filter(|(name, _)| shown.iter().any(|p| positive(term(p, name))))
        .collect();
    let values: Vec<f64> = shown
        .iter()
        .flat_map(|p| series.iter().map(|(n, _)| f64::from(term(p, n))))
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    if shown.is_empty() || values.is_empty() {
        return html! { p { "No losses logged yet." } };
    }
    let lo = values
        .iter()
        .copied()
        .fold(f64::MAX, f64::min)
        .log10()
        .floor();
    let hi = values
        .iter()
        .copied()
        .fold(f64::MIN, f64::max)
        .log10()
        .ceil()
        .max(lo + 1.0);
    let (s0, s1) = (
        shown.first().map_or(0, |p| p.step) as f64,
        shown.last().map_or(1, |p| p.step) as f64,
    );
    let x = |step: u64| left + (step as f64 - s0) / (s1 - s0).max(1.0) * (w - left - 10.0);
    let y = |v: f64| 8.0 + (hi - v.log10()) / (hi - lo) * (h - bottom - 8.0);
    html! {
        svg.losses viewBox=(format!("0 0 {w} {h}")) width="100%" role="img"
            aria-label="loss curves" style="max-width:800px;background:#fff;border:1px solid #ddd" {
            @for d in (lo as i32)..=(hi as i32) {
                @let yy = y(10f64.powi(d));
                line x1=(left) x2=(w - 10.0) y1=(yy) y2=(yy) stroke="#eee" {}
                text x=(left - 4.0) y=(yy + 4.0) text-anchor="end" font-size="11" { "1e" (d) }
            }
            text x=(left) y=(h - 6.0) font-size="11" { "step " (s0) }
            text x=(w - 10.0) y=(h - 6.0) font-size="11" text-anchor="end" { "step " (s1) }
            @for (name, colour) in &series {
                @let pts: Vec<String> = shown.iter()
                    .filter(|p| positive(term(p, name)))
                    .map(|p| format!("{:.1},{:.1}", x(p.step), y(f64::from(term(p, name)))))
                    .collect();
                polyline data-term=(name) points=(pts.join(" ")) fill="none" stroke=(colour)
                    stroke-width="1.5" {}
            }
        }
        p.legend {
            @for (name, colour) in &series {
                span style=(format!("color:{colour};margin-right:1em")) { "■ " (name) }
            }
        }
    }
}

/// The samples a job page relights: its farm dataset's (or any job's) test split, else train.
fn validation_samples(app: &App, dataset: &str) -> Vec<SampleRecord> {
    let job = dataset
        .strip_prefix("farm://")
        .and_then(|rest| rest.rsplit('/').next())
        .filter(|j| !j.is_empty());
    let list = |split: Option<&str>| {
        app.scheduler
            .samples()
            .list(job, split, 0, VALIDATION_SAMPLES)
            .map(|(r, _)| r)
            .unwrap_or_default()
    };
    let test = list(Some("test"));
    if test.is_empty() {
        list(None)
    } else {
        test
    }
}

async fn losses_fragment(app: &App, id: &str) -> Markup {
    let Some(t) = &app.trainer else {
        return no_trainer();
    };
    match t.progress(id).await {
        Ok(p) => {
            let job = p.job.unwrap_or_default();
            html! {
                p { (kind_name(job.kind)) " job, " b data-field="state" { (state_name(job.state)) }
                    ", step " (job.step) " of " (job.steps) ", dataset " code { (job.dataset) }
                    @if !job.base_job_id.is_empty() { ", adapting " a href=(format!("/trainer/{}", job.base_job_id)) { (job.base_job_id) } } }
                @if !job.error.is_empty() { p.err { (job.error) } }
                (loss_plot(&p.losses))
            }
        }
        Err(e) => html! { p.err { (e) } },
    }
}

/// `GET /trainer/ID`.
pub(super) async fn job_page(
    State(app): State<App>,
    PageSession(s): PageSession,
    Path(id): Path<String>,
) -> Response {
    let dataset = match &app.trainer {
        Some(t) => t
            .jobs()
            .await
            .ok()
            .and_then(|jobs| jobs.into_iter().find(|j| j.id == id))
            .map(|j| j.dataset)
            .unwrap_or_default(),
        None => String::new(),
    };
    let samples = validation_samples(&app, &dataset);
    let body = html! {
        h1 { "Train job " (id) }
        div data-live=(format!("/trainer/{id}/losses")) { (losses_fragment(&app, &id).await) }
        h2 { "Validation" }
        @if samples.is_empty() {
            p { "No committed sample to relight yet." }
        } @else {
            p { "Each sample's lit0 relit by the newest checkpoint under its lighting 1, next to the render under that lighting." }
            @for r in &samples {
                @let base = format!("/jobs/{}/samples/{}", r.job_id, r.index);
                div.passes data-validation=(r.index) {
                    figure { img src=(format!("{base}/lit0.png")) alt="input"; figcaption { "input: " a href=(base) { (r.job_id) " #" (r.index) } " (" (r.split) ")" } }
                    figure { img src=(format!("/trainer/{id}/relit/{}/{}", r.job_id, r.index)) alt="relit" loading="lazy"; figcaption { "relit by " (id) } }
                    figure { img src=(format!("{base}/lit1.png")) alt="ground truth"; figcaption { "rendered (ground truth)" } }
                }
            }
        }
    };
    html(
        StatusCode::OK,
        pages::layout(&format!("Train job {id}"), &s.csrf, body),
    )
}

/// `GET /trainer/ID/losses`: the state line and the plot, for the live refresh.
pub(super) async fn losses(
    State(app): State<App>,
    _: ApiSession,
    Path(id): Path<String>,
) -> Response {
    html(StatusCode::OK, losses_fragment(&app, &id).await)
}

/// `GET /trainer/ID/relit/JOB/INDEX`: that sample relit by the train job's newest checkpoint
/// (PNG), made once per checkpoint.
pub(super) async fn relit(
    State(app): State<App>,
    _: ApiSession,
    Path((id, job, index)): Path<(String, String, u64)>,
) -> Response {
    let Some(t) = app.trainer.clone() else {
        return (StatusCode::NOT_FOUND, "no trainer is configured").into_response();
    };
    match relight(&app, &t, &id, &job, index).await {
        Ok(png) => (
            [
                (header::CONTENT_TYPE, "image/png"),
                (header::CACHE_CONTROL, "no-store"),
            ],
            png.as_ref().clone(),
        )
            .into_response(),
        Err((status, e)) => {
            tracing::warn!(train_job = %id, job = %job, index, "validation relight: {e}");
            (status, e).into_response()
        }
    }
}

async fn relight(
    app: &App,
    t: &Trainer,
    id: &str,
    job: &str,
    index: u64,
) -> Result<Arc<Vec<u8>>, (StatusCode, String)> {
    let missing = |e: String| (StatusCode::NOT_FOUND, e);
    let step = t
        .latest_checkpoint(id)
        .await
        .map_err(missing)?
        .ok_or_else(|| missing(format!("train job {id} has no checkpoint yet")))?;
    let key = (id.to_owned(), step, job.to_owned(), index);
    if let Some(png) = t.relit.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return Ok(png.clone());
    }
    let rec = app
        .scheduler
        .samples()
        .get(job, index)
        .map_err(|e| missing(e.to_string()))?
        .ok_or_else(|| missing(format!("sample {index} of {job} is not committed")))?;
    let spec = super::gallery::spec_of(&rec)
        .ok_or_else(|| missing(format!("sample {index} of {job} has no sample spec")))?;
    let blobs = app.previews.blobs();
    let hash = rec.blake3.clone();
    let exr = tokio::task::spawn_blocking(move || blobs.read(&hash))
        .await
        .map_err(|e| (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
        .map_err(|e| missing(e.to_string()))?;
    let light = &spec.lighting[1];
    let req = pb::RelightRequest {
        job_id: id.to_owned(),
        image: exr,
        mask: Vec::new(),
        lighting: Some(pb::relight_request::Lighting::HdriId(light.hdri.clone())),
        rotation_deg: light.rotation_deg as f32,
        flip: light.flip,
        no_matte: true,
    };
    let mut client = t.client.clone();
    let out = match tokio::time::timeout(RELIGHT, client.relight(req)).await {
        Ok(Ok(r)) => r.into_inner(),
        Ok(Err(s)) => return Err((StatusCode::BAD_GATEWAY, t.unreachable(s.message()))),
        Err(_) => {
            return Err((
                StatusCode::GATEWAY_TIMEOUT,
                t.unreachable("no relit image within 5 min"),
            ))
        }
    };
    let png = Arc::new(out.relit_png);
    let mut cache = t.relit.lock().unwrap_or_else(|p| p.into_inner());
    if cache.len() >= CACHED_RELIGHTS {
        cache.clear();
    }
    cache.insert(key, png.clone());
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plot_draws_the_logged_terms_on_a_log_scale() {
        let points: Vec<pb::LossPoint> = (0..2000u64)
            .map(|s| pb::LossPoint {
                step: s,
                total: 10.0 / (1.0 + s as f32),
                relit: 1.0,
                ..pb::LossPoint::default()
            })
            .collect();
        let svg = loss_plot(&points).into_string();
        assert!(svg.contains("data-term=\"total\"") && svg.contains("data-term=\"relit\""));
        assert!(
            !svg.contains("data-term=\"albedo\""),
            "all-zero terms are left out"
        );
        // Decades from 1e-3 (10/2000) to 1e1.
        assert!(svg.contains(">1e-3<") && svg.contains(">1e1<"), "{svg}");
        let total = svg
            .split("data-term=\"total\" points=\"")
            .nth(1)
            .and_then(|s| s.split('"').next())
            .unwrap_or_default();
        let n = total.split(' ').count();
        assert!((400..=501).contains(&n), "{n} points drawn of 2000");
        assert!(loss_plot(&[]).into_string().contains("No losses"));
    }
}
