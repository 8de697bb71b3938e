//! The web dashboard over HTTP, in process: nothing but /metrics without a session, a wrong
//! token refused, a login that sets an HTTP-only cookie, the jobs page with a job whose name is
//! markup (shown as text), actions that need the session's CSRF token and change the job, the
//! polled JSON, the gallery's empty and broken cases, the workers page (names as text), logout,
//! and the throttle on wrong tokens.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;

use lightfarm_coordinator::dashboard::COOKIE;
use lightfarm_coordinator::scheduler::{RunState, Scheduler, WorkerHello};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

mod common;

const TOKEN: &str = "dash-token";
const HOSTILE: &str = "<script>document.title='pwned'</script><b>bold</b>";

struct Reply {
    status: u16,
    headers: HashMap<String, String>,
    body: String,
}

/// One HTTP/1.1 request; `form` is sent url-encoded as a POST.
async fn request(
    addr: SocketAddr,
    path: &str,
    cookie: Option<&str>,
    form: Option<&[(&str, &str)]>,
) -> Reply {
    let mut s = tokio::net::TcpStream::connect(addr).await.expect("connect");
    let cookie = cookie
        .map(|c| format!("Cookie: {c}\r\n"))
        .unwrap_or_default();
    let req = match form {
        Some(fields) => {
            let body: String = fields
                .iter()
                .map(|(k, v)| format!("{k}={}", urlencode(v)))
                .collect::<Vec<_>>()
                .join("&");
            format!(
                "POST {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n{cookie}Content-Type: \
                 application/x-www-form-urlencoded\r\nContent-Length: {}\r\n\r\n{body}",
                body.len()
            )
        }
        None => format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n{cookie}\r\n"),
    };
    s.write_all(req.as_bytes()).await.expect("write");
    let mut buf = String::new();
    s.read_to_string(&mut buf).await.expect("read");
    let (head, body) = buf.split_once("\r\n\r\n").expect("a response");
    let mut lines = head.lines();
    let status = lines
        .next()
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|c| c.parse().ok())
        .expect("status");
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_owned()))
        .collect();
    Reply {
        status,
        headers,
        body: body.to_owned(),
    }
}

fn urlencode(v: &str) -> String {
    v.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// The session's CSRF token, from a page's forms.
fn csrf(page: &str) -> String {
    let at = page
        .find("name=\"csrf\" value=\"")
        .expect("a form with a CSRF field")
        + 19;
    page[at..].split('"').next().expect("value").to_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn login_jobs_actions_and_escaping() {
    let dir = tempfile::tempdir().expect("tmp");
    let served = common::serve_dashboard(dir.path(), TOKEN).await;
    let (scheduler, addr): (Arc<Scheduler>, _) = (served.scheduler, served.web);
    let spec =
        format!("name = {HOSTILE:?}\nseed = 1\ncount = 3\nwidth = 16\nheight = 16\nspp = 1\n");
    let job = scheduler.submit(&spec, 0, 0.0).expect("submit").record.id;

    // Without a session: /metrics only.
    assert_eq!(request(addr, "/metrics", None, None).await.status, 200);
    for path in ["/", "/jobs/x"] {
        let r = request(addr, path, None, None).await;
        assert_eq!(
            (r.status, r.headers.get("location").map(String::as_str)),
            (303, Some("/login")),
            "{path}"
        );
    }
    assert_eq!(request(addr, "/api/jobs", None, None).await.status, 401);
    let r = request(addr, "/jobs/x/cancel", None, Some(&[("csrf", "x")])).await;
    assert_eq!(r.status, 303);

    // A wrong token: refused, no cookie.
    let r = request(addr, "/login", None, Some(&[("token", "guess")])).await;
    assert_eq!(r.status, 401);
    assert!(r.body.contains("not this coordinator") && !r.headers.contains_key("set-cookie"));

    // The right one: an HTTP-only session cookie.
    let r = request(addr, "/login", None, Some(&[("token", TOKEN)])).await;
    assert_eq!(r.status, 303, "{}", r.body);
    let set = r
        .headers
        .get("set-cookie")
        .expect("a session cookie")
        .clone();
    assert!(
        set.contains("HttpOnly") && set.contains("SameSite=Strict"),
        "{set}"
    );
    let cookie = set.split(';').next().expect("name=value").to_owned();
    assert!(cookie.starts_with(COOKIE));
    let cookie = Some(cookie.as_str());

    // The jobs page: the job, its progress, its name as text.
    let page = request(addr, "/", cookie, None).await;
    assert_eq!(page.status, 200);
    assert!(
        page.body.contains(&job) && page.body.contains("<progress max=\"3\" value=\"0\">"),
        "{}",
        page.body
    );
    assert!(
        page.body.contains("&lt;script&gt;document.title="),
        "{}",
        page.body
    );
    assert!(!page.body.contains("<script>document") && !page.body.contains("<b>bold"));
    let token = csrf(&page.body);

    // Actions need the session's CSRF token.
    let pause = format!("/jobs/{job}/pause");
    let r = request(addr, &pause, cookie, Some(&[("csrf", "forged")])).await;
    assert_eq!(r.status, 403);
    assert_eq!(
        scheduler.job(&job, 0.0).expect("job").record.run,
        RunState::Running
    );
    let r = request(addr, &pause, cookie, Some(&[("csrf", &token)])).await;
    assert_eq!(
        (r.status, r.headers.get("location").cloned()),
        (303, Some(format!("/jobs/{job}")))
    );
    assert_eq!(
        scheduler.job(&job, 0.0).expect("job").record.run,
        RunState::Paused
    );
    let page = request(addr, &format!("/jobs/{job}"), cookie, None).await;
    assert!(
        page.body.contains("data-field=\"state\">paused<"),
        "{}",
        page.body
    );
    assert!(page.body.contains("&lt;b&gt;bold") && page.body.contains("count = 3"));
    let json = request(addr, "/api/jobs", cookie, None).await;
    let rows: serde_json::Value = serde_json::from_str(&json.body).expect("json");
    assert_eq!(rows[0]["state"], "paused");
    assert_eq!(rows[0]["count"], 3);

    let priority = format!("/jobs/{job}/priority");
    let r = request(
        addr,
        &priority,
        cookie,
        Some(&[("csrf", &token), ("priority", "7")]),
    )
    .await;
    assert_eq!(r.status, 303);
    assert_eq!(scheduler.job(&job, 0.0).expect("job").record.priority, 7);
    let r = request(
        addr,
        &priority,
        cookie,
        Some(&[("csrf", &token), ("priority", "<i>high</i>")]),
    )
    .await;
    assert_eq!(r.status, 409);
    assert!(
        r.body.contains("&lt;i&gt;high") && r.body.contains("not a whole number"),
        "{}",
        r.body
    );
    let r = request(addr, "/jobs/nope/cancel", cookie, Some(&[("csrf", &token)])).await;
    assert_eq!(r.status, 404);
    assert!(r.body.contains("unknown job"), "{}", r.body);
    let r = request(
        addr,
        &format!("/jobs/{job}/cancel"),
        cookie,
        Some(&[("csrf", &token)]),
    )
    .await;
    assert_eq!(r.status, 303);
    let r = request(
        addr,
        &format!("/jobs/{job}/resume"),
        cookie,
        Some(&[("csrf", &token)]),
    )
    .await;
    assert_eq!(r.status, 409, "a cancelled job does not resume");

    // The gallery: empty, then a committed sample's strip; its images come from its EXR, and
    // a sample whose EXR is missing says which.
    let page = request(addr, &format!("/jobs/{job}"), cookie, None).await;
    assert!(
        page.body.contains("No sample committed yet"),
        "{}",
        page.body
    );
    let r = request(addr, &format!("/jobs/{job}/samples/0"), cookie, None).await;
    assert_eq!(r.status, 404);
    assert!(r.body.contains("sample 0 of") && r.body.contains("not committed"));
    let missing = "ab".repeat(32);
    scheduler
        .samples()
        .commit(&job, 0, "train", &missing, 10, "{}", 0.0)
        .expect("commit");
    let grid = request(addr, &format!("/jobs/{job}/gallery?page=0"), cookie, None).await;
    assert!(
        grid.body.contains("data-sample=\"0\"") && grid.body.contains("1 committed"),
        "{}",
        grid.body
    );
    let r = request(
        addr,
        &format!("/jobs/{job}/samples/0/strip.png"),
        cookie,
        None,
    )
    .await;
    assert_eq!(r.status, 404);
    assert!(r.body.contains(&missing), "{}", r.body);
    let r = request(addr, &format!("/jobs/{job}/samples/0/x.txt"), cookie, None).await;
    assert_eq!(r.status, 404);
    assert!(r.body.contains("not a file of a sample"), "{}", r.body);
    assert_eq!(
        request(addr, &format!("/jobs/{job}/gallery"), None, None)
            .await
            .status,
        401
    );

    // Workers: a name with markup in it is text.
    let evil = "<img src=x onerror=alert(1)>";
    scheduler
        .register_worker(
            WorkerHello {
                name: evil.into(),
                device: "NVIDIA H200 (discrete-gpu)".into(),
                ..WorkerHello::default()
            },
            lightfarm_coordinator::service::now_unix(),
        )
        .expect("register");
    let page = request(addr, "/workers", cookie, None).await;
    assert_eq!(page.status, 200);
    assert!(
        page.body.contains("&lt;img src=x onerror=alert(1)&gt;")
            && !page.body.contains(evil)
            && page.body.contains(">idle<")
            && page.body.contains("NVIDIA H200"),
        "{}",
        page.body
    );
    assert_eq!(
        request(addr, "/workers/table", None, None).await.status,
        401
    );

    // Logout ends the session.
    let r = request(addr, "/logout", cookie, Some(&[("csrf", &token)])).await;
    assert_eq!(r.status, 303);
    assert_eq!(request(addr, "/", cookie, None).await.status, 303);

    // Guessing is throttled: after a burst of wrong tokens even the right one waits.
    let mut statuses = Vec::new();
    for _ in 0..12 {
        let r = request(addr, "/login", None, Some(&[("token", "guess")])).await;
        statuses.push(r.status);
    }
    assert_eq!(statuses.last(), Some(&429), "{statuses:?}");
    let r = request(addr, "/login", None, Some(&[("token", TOKEN)])).await;
    assert_eq!(r.status, 429);
    assert!(r.body.contains("Too many wrong tokens"), "{}", r.body);
}

/// A job of 10,000 committed samples: the job page stays small (one page of the gallery, 24
/// samples) and the pager reaches the last page.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_big_job_pages_its_gallery() {
    let dir = tempfile::tempdir().expect("tmp");
    let served = common::serve_dashboard(dir.path(), TOKEN).await;
    let (scheduler, addr): (Arc<Scheduler>, _) = (served.scheduler, served.web);
    let spec = "name = \"big\"\nseed = 1\ncount = 10000\nwidth = 16\nheight = 16\nspp = 1\n";
    let job = scheduler.submit(spec, 0, 0.0).expect("submit").record.id;
    let index = scheduler.samples().clone();
    let j = job.clone();
    tokio::task::spawn_blocking(move || {
        for i in 0..10_000u64 {
            index
                .commit(&j, i, "train", &format!("{:064x}", i + 1), 1, "{}", 0.0)
                .expect("commit");
        }
    })
    .await
    .expect("join");
    let r = request(addr, "/login", None, Some(&[("token", TOKEN)])).await;
    let cookie = r.headers.get("set-cookie").expect("cookie").clone();
    let cookie = Some(cookie.split(';').next().expect("name=value"));
    let started = std::time::Instant::now();
    let page = request(addr, &format!("/jobs/{job}"), cookie, None).await;
    let took = started.elapsed();
    assert_eq!(page.status, 200);
    assert_eq!(page.body.matches("data-sample=").count(), 24);
    assert!(page.body.contains("of 10000 committed"), "{}", page.body);
    assert!(
        page.body.len() < 40_000,
        "the job page is {} bytes",
        page.body.len()
    );
    eprintln!(
        "job page with 10,000 samples: {} bytes in {took:?}",
        page.body.len()
    );
    // 10,000 / 24 → 417 pages; the last holds the remaining 16.
    assert!(page.body.contains(&format!("/jobs/{job}?page=416")));
    let last = request(addr, &format!("/jobs/{job}/gallery?page=416"), cookie, None).await;
    assert_eq!(last.body.matches("data-sample=").count(), 16);
    assert!(last.body.contains("data-sample=\"9999\""));
}
