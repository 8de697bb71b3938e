//! The dashboard in a real browser (headless Chromium over the DevTools protocol) against an
//! in-process coordinator: the login page refuses a wrong token; after login the job appears
//! with its progress; a job named with `<script>` shows that text and runs nothing; Pause
//! changes the state on the page; a change made elsewhere reaches the open page without a
//! reload. `LIGHTFARM_DASHBOARD_SCREENSHOT=FILE` also saves the jobs page as a PNG.

mod common;

use std::sync::Arc;

use common::browser::{self, Browser};
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
    let (coordinator, addr) = rt.block_on(common::serve_dashboard(dir.path(), TOKEN));
    let base = format!("http://{addr}");
    let scheduler: Arc<Scheduler> = coordinator.scheduler().clone();
    let quiet = scheduler
        .submit(
            "name = \"studio-batch\"\nseed = 2\ncount = 5\nwidth = 16\nheight = 16\nspp = 1\n",
            1,
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
    let row = format!("document.querySelector('[data-job=\"{job}\"]')");
    assert_eq!(b.eval(&format!("{row}.querySelector('progress').max")), 4);
    assert_eq!(
        b.eval(&format!(
            "{row}.querySelector('[data-field=state]').textContent"
        )),
        "running"
    );
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
    if let Ok(path) = std::env::var("LIGHTFARM_DASHBOARD_SCREENSHOT") {
        std::fs::write(&path, b.screenshot()).expect("screenshot");
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
