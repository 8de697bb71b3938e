//! The dashboard's HTML, server-rendered with maud (every interpolated value is escaped, so a
//! job name or failure reason with markup in it shows as text). No external files: the CSS
//! and the few lines of script that refresh the numbers are inline.

use maud::{html, Markup, PreEscaped, DOCTYPE};

use crate::scheduler::{JobStatus, RunState};

const STYLE: &str = "
body{font:15px/1.4 system-ui,sans-serif;margin:0;color:#222;background:#f6f6f4}
header{background:#223;color:#eee;padding:.6em 1em;display:flex;gap:1em;align-items:center}
header a{color:#eee;text-decoration:none;font-weight:600}
header form{margin-left:auto}
main{padding:1em;max-width:1100px;margin:auto}
.scroll{overflow-x:auto}
table{border-collapse:collapse;width:100%;background:#fff}
th,td{padding:.35em .6em;border-bottom:1px solid #ddd;text-align:left;white-space:nowrap}
td.reason{white-space:pre-wrap;word-break:break-word}
td.name{white-space:normal;word-break:break-word;min-width:9em}
progress{width:8em}
pre{background:#fff;padding:.8em;overflow-x:auto;border:1px solid #ddd}
button{font:inherit;padding:.15em .6em}
form.inline{display:inline}
.err{color:#a00;font-weight:600}
code{word-break:break-all}
@media (max-width:600px){.wide{display:none}}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(300px,1fr));gap:.6em}
.grid figure{margin:0;background:#fff;border:1px solid #ddd;padding:.3em}
.grid img{width:100%;height:auto;display:block}
.passes img{width:100%;height:auto;display:block}
.passes{display:grid;grid-template-columns:repeat(auto-fill,minmax(240px,1fr));gap:.6em}
.passes figure{margin:0}
nav.pager a,nav.pager b{margin-right:.5em}
.state-lost{color:#a00;font-weight:600}
";

/// Keeps the numbers of the jobs on the page current: polls /api/jobs and writes text only.
const REFRESH: &str = "
async function refresh(){
  try{
    const r=await fetch('/api/jobs',{credentials:'same-origin'});
    if(!r.ok)return;
    for(const j of await r.json()){
      document.querySelectorAll('[data-job=\"'+CSS.escape(j.id)+'\"]').forEach(row=>{
        for(const k of ['state','done','leased','queued','failed','rate','eta','priority']){
          const c=row.querySelector('[data-field=\"'+k+'\"]');
          if(c)c.textContent=j[k];
        }
        const p=row.querySelector('progress');
        if(p){p.max=j.count;p.value=j.done;}
      });
    }
  }catch(e){}
}
setInterval(refresh,2000);
// Parts of a page marked data-live are fragments the server renders (escaped like the page).
async function live(){
  for(const el of document.querySelectorAll('[data-live]')){
    try{
      const r=await fetch(el.dataset.live,{credentials:'same-origin'});
      if(!r.ok)continue;
      const t=await r.text();
      if(el.dataset.shown!==t){el.innerHTML=t;el.dataset.shown=t;}
    }catch(e){}
  }
}
setInterval(live,2000);
";

fn page(title: &str, csrf: Option<&str>, body: Markup) -> Markup {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                title { (title) " · lightfarm" }
                style { (PreEscaped(STYLE)) }
            }
            body {
                header {
                    a href="/" { "lightfarm" }
                    a href="/" { "Jobs" }
                    a href="/workers" { "Workers" }
                    a href="/trainer" { "Trainer" }
                    @if let Some(csrf) = csrf {
                        form method="post" action="/logout" {
                            input type="hidden" name="csrf" value=(csrf);
                            button { "Log out" }
                        }
                    }
                }
                main { (body) }
                @if csrf.is_some() {
                    script { (PreEscaped(REFRESH)) }
                }
            }
        }
    }
}

pub fn login(error: Option<&str>) -> Markup {
    page(
        "Log in",
        None,
        html! {
            h1 { "Log in" }
            p { "The coordinator's bearer token (" code { "--token" } " / "
                code { "LIGHTFARM_TOKEN" } ")." }
            @if let Some(e) = error { p.err id="error" { (e) } }
            form method="post" action="/login" {
                input type="password" name="token" autocomplete="current-password" autofocus;
                " "
                button type="submit" { "Log in" }
            }
        },
    )
}

/// What a job is doing, in one word.
pub fn state(j: &JobStatus) -> &'static str {
    match j.record.run {
        RunState::Cancelled => "cancelled",
        _ if j.finished() => "completed",
        RunState::Paused => "paused",
        RunState::Running => "running",
    }
}

pub fn eta(j: &JobStatus) -> String {
    let s = j.eta_seconds;
    if j.finished() || !s.is_finite() || s <= 0.0 {
        "–".into()
    } else if s < 90.0 {
        format!("{s:.0} s")
    } else if s < 5400.0 {
        format!("{:.0} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}

pub fn rate(j: &JobStatus) -> String {
    format!("{:.2}", j.samples_per_second)
}

fn actions(j: &JobStatus, csrf: &str) -> Markup {
    let id = &j.record.id;
    html! {
        @for (action, label, shown) in [
            ("pause", "Pause", j.record.run == RunState::Running && !j.finished()),
            ("resume", "Resume", j.record.run == RunState::Paused && !j.finished()),
            ("cancel", "Cancel", j.record.run != RunState::Cancelled && !j.finished()),
        ] {
            @if shown {
                form.inline method="post" action=(format!("/jobs/{id}/{action}")) {
                    input type="hidden" name="csrf" value=(csrf);
                    button type="submit" data-action=(action) { (label) }
                }
                " "
            }
        }
    }
}

pub fn jobs(jobs: &[JobStatus], csrf: &str) -> Markup {
    page(
        "Jobs",
        Some(csrf),
        html! {
            h1 { "Jobs" }
            @if jobs.is_empty() {
                p { "No jobs yet: " code { "lightfarm submit dataset.toml" } }
            } @else {
                div.scroll { table {
                    tr {
                        th { "job" } th { "state" } th { "progress" } th { "done" }
                        th.wide { "leased" } th.wide { "queued" } th { "failed" }
                        th.wide { "samples/s" } th { "ETA" } th.wide { "priority" } th {}
                    }
                    @for j in jobs {
                        tr data-job=(j.record.id) {
                            td.name { a href=(format!("/jobs/{}", j.record.id)) { (j.record.name) }
                                 br; small { (j.record.id) } }
                            td data-field="state" { (state(j)) }
                            td { progress max=(j.record.count) value=(j.done) {} }
                            td { span data-field="done" { (j.done) } " / " (j.record.count) }
                            td.wide data-field="leased" { (j.leased) }
                            td.wide data-field="queued" { (j.queued) }
                            td data-field="failed" { (j.failed) }
                            td.wide data-field="rate" { (rate(j)) }
                            td data-field="eta" { (eta(j)) }
                            td.wide data-field="priority" { (j.record.priority) }
                            td { (actions(j, csrf)) }
                        }
                    }
                } }
            }
        },
    )
}

pub fn job(j: &JobStatus, samples: Markup, csrf: &str) -> Markup {
    let id = &j.record.id;
    page(
        &j.record.name,
        Some(csrf),
        html! {
            h1 { (j.record.name) }
            div.scroll { table {
                tr data-job=(id) {
                    td { "id " code { (id) } }
                    td { "state " b data-field="state" { (state(j)) } }
                    td { progress max=(j.record.count) value=(j.done) {} " "
                         span data-field="done" { (j.done) } " / " (j.record.count) }
                    td { "leased " span data-field="leased" { (j.leased) } }
                    td { "queued " span data-field="queued" { (j.queued) } }
                    td { "failed " span data-field="failed" { (j.failed) } }
                    td { "samples/s " span data-field="rate" { (rate(j)) } }
                    td { "ETA " span data-field="eta" { (eta(j)) } }
                    td { "priority " span data-field="priority" { (j.record.priority) } }
                }
            } }
            p {
                (actions(j, csrf))
                form.inline method="post" action=(format!("/jobs/{id}/priority")) {
                    input type="hidden" name="csrf" value=(csrf);
                    input type="number" name="priority" value=(j.record.priority) style="width:5em";
                    " "
                    button type="submit" { "Set priority" }
                }
            }
            @if !j.record.blocklist.is_empty() {
                p { "Workers blocklisted for this job: "
                    @for (k, w) in j.record.blocklist.iter().enumerate() {
                        @if k > 0 { ", " } code { (w) }
                    }
                }
            }
            h2 { "Samples" }
            (samples)
            h2 { "Failures" }
            @if j.recent_failures.is_empty() {
                p { "None." }
            } @else {
                div.scroll { table {
                    tr { th { "sample" } th { "worker" } th { "reason" } }
                    @for (index, f) in &j.recent_failures {
                        tr { td { (index) } td { (f.worker) } td.reason { (f.reason) } }
                    }
                } }
            }
            h2 { "Spec" }
            pre { (j.record.spec_toml) }
        },
    )
}

/// A page of the dashboard's layout (header with log-out form, live refresh) for other modules.
pub fn layout(title: &str, csrf: &str, body: Markup) -> Markup {
    page(title, Some(csrf), body)
}

/// An error page: the status line's words and what went wrong.
pub fn error(title: &str, message: &str, csrf: Option<&str>) -> Markup {
    page(
        title,
        csrf,
        html! {
            h1 { (title) }
            p.err { (message) }
            p { a href="/" { "Back to the jobs" } }
        },
    )
}
