//! A job's committed samples in the dashboard: a paginated grid of thumbnail strips (lit0 |
//! lit1 | albedo | normal | normal_lens | mask), a page per sample with every pass at full
//! size, its metadata and its EXR. Images come from [`super::preview`], made once per sample.
//! A page lists a fixed number of samples however big the job is; the grid is a live fragment,
//! so samples appear while the job renders.

use axum::extract::{Path, Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use lightfarm_scene::expand::SampleSpec;
use lightfarm_store::SampleRecord;
use maud::{html, Markup};
use serde::Deserialize;

use super::preview::{thumb_size, PASSES};
use super::session::{ApiSession, PageSession};
use super::{coord_error, html, pages, App};
use crate::error::CoordError;
use crate::service::now_unix;

/// Samples per gallery page.
pub const PER_PAGE: u64 = 24;

#[derive(Deserialize, Default)]
pub struct PageQuery {
    #[serde(default)]
    pub page: u64,
}

/// The sample spec stored with a committed sample (`{"sample": ..., "stats": ..}`).
pub(super) fn spec_of(rec: &SampleRecord) -> Option<SampleSpec> {
    let meta: serde_json::Value = serde_json::from_str(&rec.metadata_json).ok()?;
    serde_json::from_value(meta.get("sample")?.clone()).ok()
}

fn sample_url(job: &str, index: u64) -> String {
    format!("/jobs/{job}/samples/{index}")
}

/// The gallery section of a job page: its live grid at `page`.
pub(super) fn section(app: &App, job: &str, page: u64) -> Result<Markup, CoordError> {
    let grid = grid(app, job, page)?;
    Ok(html! {
        div.gallery data-live=(format!("/jobs/{job}/gallery?page={page}")) { (grid) }
    })
}

fn pager(job: &str, page: u64, pages: u64) -> Markup {
    let link = |p: u64| format!("/jobs/{job}?page={p}");
    let near: Vec<u64> = (page.saturating_sub(3)..(page + 4).min(pages)).collect();
    html! {
        nav.pager {
            @if page > 0 { a href=(link(0)) { "« first" } a href=(link(page - 1)) { "‹ previous" } }
            @for p in near {
                @if p == page { b { (p + 1) } } @else { a href=(link(p)) { (p + 1) } }
            }
            @if page + 1 < pages {
                a href=(link(page + 1)) { "next ›" } a href=(link(pages - 1)) { "last »" }
            }
        }
    }
}

fn grid(app: &App, job: &str, page: u64) -> Result<Markup, CoordError> {
    let (records, total) =
        app.scheduler
            .samples()
            .list(Some(job), None, page * PER_PAGE, PER_PAGE as usize)?;
    let pages = total.div_ceil(PER_PAGE);
    Ok(html! {
        @if total == 0 {
            p { "No sample committed yet." }
        } @else {
            p { "Samples " (page * PER_PAGE + 1) "–" (page * PER_PAGE + records.len() as u64)
                " of " (total) " committed: lit0 | lit1 | albedo | normal | normal_lens | mask." }
            (pager(job, page, pages))
            div.grid {
                @for rec in &records {
                    @let (w, h) = spec_of(rec)
                        .map(|s| thumb_size(s.render.width as usize, s.render.height as usize))
                        .unwrap_or((96, 96));
                    figure data-sample=(rec.index) {
                        a href=(sample_url(job, rec.index)) {
                            img src=(format!("{}/strip.png", sample_url(job, rec.index)))
                                width=(w * PASSES.len()) height=(h) loading="lazy"
                                alt=(format!("sample {}: its six passes", rec.index));
                        }
                        figcaption { "#" (rec.index) " · " (rec.split) }
                    }
                }
            }
        }
    })
}

/// `GET /jobs/ID/gallery?page=N`: the grid alone, for the live refresh.
pub(super) async fn fragment(
    State(app): State<App>,
    ApiSession(s): ApiSession,
    Path(job): Path<String>,
    Query(q): Query<PageQuery>,
) -> Response {
    if let Err(e) = app.scheduler.job(&job, now_unix()) {
        return coord_error(&e, &s);
    }
    match grid(&app, &job, q.page) {
        Ok(m) => html(StatusCode::OK, m),
        Err(e) => coord_error(&e, &s),
    }
}

fn record(app: &App, job: &str, index: u64) -> Result<SampleRecord, CoordError> {
    app.scheduler.job(job, now_unix())?;
    app.scheduler
        .samples()
        .get(job, index)?
        .ok_or_else(|| CoordError::NotFound(format!("sample {index} of {job} is not committed")))
}

/// `GET /jobs/ID/samples/N`: every pass at full size, the metadata, the EXR link.
pub(super) async fn sample_page(
    State(app): State<App>,
    PageSession(s): PageSession,
    Path((job, index)): Path<(String, u64)>,
) -> Response {
    let rec = match record(&app, &job, index) {
        Ok(r) => r,
        Err(e) => return coord_error(&e, &s),
    };
    // The EXR header holds the assembled scene's materials; reading it makes the previews.
    let header: serde_json::Value = match app.previews.file(&rec.blake3, "header").await {
        Ok(bytes) => serde_json::from_slice(&bytes).unwrap_or_default(),
        Err(e) => {
            return coord_error(&CoordError::Storage(e), &s);
        }
    };
    let meta: serde_json::Value = serde_json::from_str(&rec.metadata_json).unwrap_or_default();
    let pretty = |v: Option<&serde_json::Value>| {
        v.and_then(|v| serde_json::to_string_pretty(v).ok())
            .unwrap_or_else(|| "–".into())
    };
    let url = sample_url(&job, index);
    let body = html! {
        h1 { "Sample " (index) " of " a href=(format!("/jobs/{job}")) { (job) } }
        p {
            a href=(format!("{url}/sample.exr")) download { "Download the EXR" }
            " (" (rec.size / 1024) " KiB, BLAKE3 " code { (rec.blake3) } ")"
        }
        @if let Some(spec) = spec_of(&rec) { (facts(&spec, &rec, &meta)) }
        div.passes {
            @for p in PASSES {
                figure {
                    a href=(format!("{url}/{p}.png")) {
                        img src=(format!("{url}/{p}.png")) alt=(p) loading="lazy";
                    }
                    figcaption { (p) }
                }
            }
        }
        p { small { "Radiance passes are exposed each on its own for viewing; the EXR has the values." } }
        details { summary { "Materials of the rendered scene" } pre { (pretty(header.get("materials"))) } }
        details { summary { "The sample spec" } pre { (pretty(meta.get("sample"))) } }
        details { summary { "Render statistics" } pre { (pretty(meta.get("stats"))) } }
    };
    html(
        StatusCode::OK,
        pages::layout(&format!("Sample {index} of {job}"), &s.csrf, body),
    )
}

fn facts(spec: &SampleSpec, rec: &SampleRecord, meta: &serde_json::Value) -> Markup {
    let committed = chrono_free_utc(rec.committed_unix);
    html! {
        div.scroll { table {
            tr { th { "split" } td { (rec.split) } }
            tr { th { "identity" } td { (spec.identity) } }
            tr { th { "head" } td.name { (spec.head.id) ", expression " (spec.head.expression.name)
                @if spec.head.synthetic.is_some() { " (a generated person)" } } }
            tr { th { "hair" } td.name { (spec.hair.style) ", melanin "
                (format!("{:.2}", spec.hair.melanin)) ", redness " (format!("{:.2}", spec.hair.melanin_redness))
                ", density " (format!("{:.2}", spec.hair.density)) ", " (format!("{:.0}", spec.hair.length_m * 100.0)) " cm" } }
            @if let Some(g) = &spec.garment { tr { th { "garment" } td.name { (g.id) ", colour "
                (format!("({:.2}, {:.2}, {:.2})", g.color_rgb[0], g.color_rgb[1], g.color_rgb[2]))
                ", roughness " (format!("{:.2}", g.roughness)) } } }
            @if let Some(g) = &spec.glasses { tr { th { "glasses" } td { (g.id) } } }
            @if let Some(h) = &spec.headset { tr { th { "headset" } td { (h.id) } } }
            @for (k, l) in spec.lighting.iter().enumerate() {
                tr { th { "lighting " (k) } td { (l.hdri) ", rotated " (format!("{:.1}", l.rotation_deg)) "°"
                    @if l.flip { ", flipped" } } }
            }
            tr { th { "camera" } td { "yaw " (format!("{:.1}", spec.camera.yaw_deg)) "°, pitch "
                (format!("{:.1}", spec.camera.pitch_deg)) "°, " (format!("{:.2}", spec.camera.radius_m))
                " m, fov " (format!("{:.1}", spec.camera.fov_deg)) "°" } }
            tr { th { "render" } td { (spec.render.width) "×" (spec.render.height) ", "
                (spec.render.spp) " spp, seed " (spec.render.seed) } }
            tr { th { "worker" } td { (meta.get("worker").and_then(|w| w.as_str()).unwrap_or("–")) } }
            tr { th { "committed" } td { (committed) } }
        } }
    }
}

/// `YYYY-MM-DD hh:mm:ss UTC` of a Unix time (civil-from-days, no calendar crate needed).
fn chrono_free_utc(unix: f64) -> String {
    let secs = unix.max(0.0) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// `GET /jobs/ID/samples/N/FILE`: `sample.exr`, `strip.png` or `PASS.png`.
pub(super) async fn sample_file(
    State(app): State<App>,
    _: ApiSession,
    Path((job, index, file)): Path<(String, u64, String)>,
) -> Response {
    let rec = match record(&app, &job, index) {
        Ok(r) => r,
        Err(e) => return (StatusCode::NOT_FOUND, e.to_string()).into_response(),
    };
    // Committed bytes never change, and neither do images made from them.
    let cache = (header::CACHE_CONTROL, "private, max-age=86400");
    if file == "sample.exr" {
        let blobs = app.previews.blobs();
        let hash = rec.blake3.clone();
        return match tokio::task::spawn_blocking(move || blobs.read(&hash)).await {
            Ok(Ok(bytes)) => (
                [
                    (header::CONTENT_TYPE, "image/x-exr".to_owned()),
                    (
                        header::CONTENT_DISPOSITION,
                        format!("attachment; filename=\"{job}-{index:06}.exr\""),
                    ),
                    (cache.0, cache.1.to_owned()),
                ],
                bytes,
            )
                .into_response(),
            Ok(Err(e)) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
            Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
        };
    }
    let Some(name) = file.strip_suffix(".png") else {
        return (
            StatusCode::NOT_FOUND,
            format!("`{file}` is not a file of a sample (sample.exr, strip.png, PASS.png)"),
        )
            .into_response();
    };
    match app.previews.file(&rec.blake3, name).await {
        Ok(bytes) => ([(header::CONTENT_TYPE, "image/png"), cache], bytes).into_response(),
        Err(e) => {
            tracing::warn!(job = %job, index, "preview: {e}");
            (StatusCode::NOT_FOUND, e).into_response()
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn utc_dates_are_civil() {
        assert_eq!(super::chrono_free_utc(0.0), "1970-01-01 00:00:00 UTC");
        assert_eq!(
            super::chrono_free_utc(1_796_437_037.0),
            "2026-12-05 02:17:17 UTC"
        );
        assert_eq!(
            super::chrono_free_utc(951_782_400.0),
            "2000-02-29 00:00:00 UTC"
        );
    }
}
