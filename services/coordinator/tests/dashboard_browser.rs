//! The dashboard in a real browser (headless Chromium over the DevTools protocol) against an
//! in-process coordinator and a render worker that renders two tiny samples: the login page
//! refuses a wrong token; samples committed while a job's page is open appear in its gallery
//! without a reload, and a thumbnail decodes as an image of the right size; a sample's page
//! shows its passes at full size and downloads its EXR; the workers page shows the worker and
//! what it rendered; after login the job appears with its progress; a job named with
//! `<script>` shows that text and runs nothing; Pause changes the state on the page; a change
//! made elsewhere reaches the open page without a reload. `LIGHTFARM_DASHBOARD_SCREENSHOT=DIR`
//! also saves the jobs, job and workers pages there as PNGs.

mod common;

use std::sync::Arc;

use common::browser::{self, Browser};
use lightfarm_coordinator::dashboard::preview::thumb_size;
use lightfarm_coordinator::scheduler::{RunState, Scheduler};

const TOKEN: &str = "browser-token";
const HOSTILE: &str = "<script>document.title='pwned'</script>portraits";

#[test]
fn the_dashboard_in_chromium() {
    let Some(chromium) = browser::find() else {
        return;
    };
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let dir = tempfile::tempdir().expect("tmp");
    let served = rt.block_on(common::serve_dashboard(dir.path(), TOKEN));
    let base = format!("http://{}", served.web);
    let scheduler: Arc<Scheduler> = served.scheduler.clone();
    let shots = std::env::var_os("LIGHTFARM_DASHBOARD_SCREENSHOT").map(std::path::PathBuf::from);
    let quiet = scheduler
        .submit(
            "name = \"studio-batch\"\nseed = 2\ncount = 5\nwidth = 16\nheight = 16\nspp = 1\n",
            -1,
            0.0,
        )
        .expect("submit")
        .record
        .id;
    let spec =
        format!("name = {HOSTILE:?}\nseed = 1\ncount = 4\nwidth = 16\nheight = 16\nspp = 1\n");
    let job = scheduler.submit(&spec, 0, 0.0).expect("submit").record.id;

    let mut b = Browser::launch(&chromium);
    b.navigate(&format!("{base}/"));
    b.wait_for(
        "location.pathname === '/login'",
        "the redirect to the login page",
    );

    let login = |b: &mut Browser, token: &str| {
        b.eval(&format!(
            "document.querySelector('input[name=token]').value = {token:?}; \
             document.querySelector('form[action=\"/login\"]').submit(); true"
        ));
    };
    login(&mut b, "not-the-token");
    b.wait_for("document.getElementById('error')", "the refusal");
    let said = b.eval("document.getElementById('error').textContent");
    assert!(
        said.as_str()
            .is_some_and(|s| s.contains("not this coordinator")),
        "{said}"
    );
    assert_eq!(b.eval("location.pathname"), "/login");

    login(&mut b, TOKEN);
    b.wait_for(
        &format!("location.pathname === '/' && document.querySelector('[data-job=\"{job}\"]')"),
        "the jobs page with the job",
    );

    // A worker renders two samples of the job while its page is open.
    b.navigate(&format!("{base}/jobs/{job}"));
    b.wait_for(
        "document.querySelector('.gallery')",
        "the job page's gallery",
    );
    let worker = rt.spawn(lightfarm_worker::run(
        lightfarm_worker::WorkerConfig {
            coordinator: served.grpc.clone(),
            token: TOKEN.into(),
            name: "browser-worker".into(),
            cache_dir: dir.path().join("worker"),
            device: "auto".into(),
            tls_ca: None,
            max_samples: Some(2),
        },
        std::future::pending(),
    ));
    b.wait_for_long(
        "document.querySelectorAll('.gallery [data-sample] img').length === 2",
        "two samples in the open page's gallery",
        std::time::Duration::from_secs(600),
    );
    rt.block_on(worker).expect("join").expect("worker");
    let (tw, th) = thumb_size(16, 16);
    let img = "document.querySelector('.gallery [data-sample=\"0\"] img')";
    b.wait_for(
        &format!("{img}.complete && {img}.naturalWidth > 0"),
        "the thumbnail to load",
    );
    assert_eq!(
        (
            b.eval(&format!("{img}.naturalWidth")),
            b.eval(&format!("{img}.naturalHeight"))
        ),
        (serde_json::json!(6 * tw), serde_json::json!(th)),
        "a strip of six {tw}x{th} tiles"
    );
    if let Some(d) = &shots {
        std::fs::write(d.join("dashboard-job.png"), b.screenshot()).expect("screenshot");
    }

    // The sample's page: every pass at the sample's size, and its EXR.
    b.eval(&format!("{img}.click(); true"));
    b.wait_for(
        &format!("location.pathname === '/jobs/{job}/samples/0'"),
        "the sample's page",
    );
    let lit = "document.querySelector('.passes img[alt=lit0]')";
    b.wait_for(
        &format!("{lit}.complete && {lit}.naturalWidth > 0"),
        "the lit0 pass",
    );
    assert_eq!(b.eval(&format!("{lit}.naturalWidth")), 16);
    assert_eq!(b.eval("document.querySelectorAll('.passes img').length"), 6);
    let rec = scheduler
        .samples()
        .get(&job, 0)
        .expect("index")
        .expect("committed");
    b.eval(
        "window.exr = null; fetch(document.querySelector('a[download]').href)\
         .then(r => r.arrayBuffer()).then(a => { const b = new Uint8Array(a); \
         window.exr = [b.length, b[0], b[1], b[2], b[3]]; }); true",
    );
    b.wait_for("window.exr", "the EXR download");
    assert_eq!(
        b.eval("window.exr"),
        serde_json::json!([rec.size, 0x76, 0x2f, 0x31, 0x01]),
        "the committed EXR, magic number first"
    );

    // The worker, finished: stopped, two samples rendered.
    b.navigate(&format!("{base}/workers"));
    let w = "document.querySelector('[data-worker=\"browser-worker\"]')";
    b.wait_for(w, "the worker's row");
    assert_eq!(
        b.eval(&format!(
            "{w}.querySelector('[data-field=rendered]').textContent"
        )),
        "2"
    );
    b.wait_for(
        &format!("{w}.querySelector('[data-field=state]').textContent.trim() === 'stopped'"),
        "the worker to show as stopped",
    );
    if let Some(d) = &shots {
        std::fs::write(d.join("dashboard-workers.png"), b.screenshot()).expect("screenshot");
    }
    b.navigate(&format!("{base}/"));
    b.wait_for(
        &format!("document.querySelector('[data-job=\"{job}\"]')"),
        "the jobs page",
    );
    let row = format!("document.querySelector('[data-job=\"{job}\"]')");
    assert_eq!(b.eval(&format!("{row}.querySelector('progress').max")), 4);
    assert_eq!(
        b.eval(&format!(
            "{row}.querySelector('[data-field=state]').textContent"
        )),
        "running"
    );
    assert_eq!(b.eval(&format!("{row}.querySelector('progress').value")), 2);
    // The name is text: the script in it neither ran nor became an element.
    assert_eq!(
        b.eval(&format!("{row}.querySelector('a').textContent")),
        HOSTILE
    );
    assert_eq!(b.eval("document.title"), "Jobs · lightfarm");
    assert_eq!(b.eval("document.querySelectorAll('main script').length"), 0);
    assert_eq!(
        b.eval("document.cookie"),
        "",
        "the session cookie is HTTP-only"
    );
    if let Some(d) = &shots {
        std::fs::write(d.join("dashboard-jobs.png"), b.screenshot()).expect("screenshot");
    }
    let png = b.screenshot();
    let shot = image::load_from_memory(&png).expect("a PNG screenshot");
    assert_eq!((shot.width(), shot.height()), (1100, 800));

    // Pause from the page.
    b.eval(&format!(
        "{row}.querySelector('button[data-action=pause]').click(); true"
    ));
    b.wait_for(
        &format!("location.pathname === '/jobs/{job}' && document.querySelector('[data-field=state]').textContent === 'paused'"),
        "the paused job's page",
    );
    assert_eq!(
        scheduler.job(&job, 0.0).expect("job").record.run,
        RunState::Paused
    );
    assert!(b
        .eval("document.querySelector('pre').textContent")
        .as_str()
        .is_some_and(|t| t.contains("count = 4")));

    // On a phone-sized screen the job page fits its width (wide tables scroll in their box).
    b.call(
        "Emulation.setDeviceMetricsOverride",
        serde_json::json!({"width": 390, "height": 844, "deviceScaleFactor": 2, "mobile": true}),
    );
    b.navigate(&format!("{base}/jobs/{job}"));
    assert_eq!(
        b.eval("document.documentElement.scrollWidth <= window.innerWidth"),
        true,
        "no sideways scrolling at 390 px: {}",
        b.eval("document.documentElement.scrollWidth")
    );
    b.call(
        "Emulation.setDeviceMetricsOverride",
        serde_json::json!({"width": 1100, "height": 800, "deviceScaleFactor": 1, "mobile": false}),
    );

    // A change made elsewhere (here the scheduler; in life `lightfarm resume`) shows up on
    // the open page through its polling, without a reload.
    b.navigate(&format!("{base}/"));
    scheduler
        .set_run_state(&job, RunState::Running, 0.0)
        .expect("resume");
    scheduler
        .set_run_state(&quiet, RunState::Cancelled, 0.0)
        .expect("cancel");
    b.wait_for(
        &format!("document.querySelector('[data-job=\"{quiet}\"] [data-field=state]').textContent === 'cancelled' && {row}.querySelector('[data-field=state]').textContent === 'running'"),
        "the polled states",
    );
}
