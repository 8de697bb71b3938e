//! Screenshots of a running dashboard, as the README shows it (scripts/dashboard-screenshot.sh
//! takes them during `lightfarm demo`): logs in with the token, waits until the first job's
//! gallery shows `MIN` thumbnails, and saves the jobs, job, sample and workers pages as PNGs.
//!
//! `cargo run -p lightfarm-coordinator --example dashboard_shot -- URL TOKEN OUT_DIR [MIN]`

#[path = "../tests/common/browser.rs"]
#[allow(dead_code)]
mod browser;

use std::path::PathBuf;
use std::time::Duration;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let [_, base, token, out, rest @ ..] = args.as_slice() else {
        eprintln!("usage: dashboard_shot URL TOKEN OUT_DIR [MIN_SAMPLES]");
        std::process::exit(2);
    };
    let min: usize = rest.first().and_then(|m| m.parse().ok()).unwrap_or(2);
    let out = PathBuf::from(out);
    std::fs::create_dir_all(&out).expect("OUT_DIR");
    let Some(chromium) = browser::find() else {
        std::process::exit(1);
    };
    let mut b = browser::Browser::launch(&chromium);
    b.navigate(&format!("{base}/login"));
    b.eval(&format!(
        "document.querySelector('input[name=token]').value = {token:?}; \
         document.querySelector('form[action=\"/login\"]').submit(); true"
    ));
    b.wait_for("location.pathname === '/'", "the login");
    b.wait_for(
        "document.querySelector('[data-job] a')",
        "a job on the jobs page",
    );
    let job = b.eval("document.querySelector('[data-job]').dataset.job");
    let job = job.as_str().expect("a job id").to_owned();
    b.navigate(&format!("{base}/jobs/{job}"));
    b.wait_for_long(
        &format!(
            "[...document.querySelectorAll('.gallery [data-sample] img')]\
             .filter(i => i.complete && i.naturalWidth > 0).length >= {min}"
        ),
        "thumbnails in the gallery",
        Duration::from_secs(1800),
    );
    let save = |b: &mut browser::Browser, name: &str| {
        let path = out.join(name);
        std::fs::write(&path, b.screenshot()).expect("write the screenshot");
        println!("{}", path.display());
    };
    // The job page scrolled to its gallery.
    b.eval("document.querySelector('.gallery').scrollIntoView(); true");
    save(&mut b, "dashboard-job.png");
    b.navigate(&format!("{base}/"));
    save(&mut b, "dashboard-jobs.png");
    b.navigate(&format!("{base}/workers"));
    b.wait_for("document.querySelector('[data-worker]')", "a worker");
    save(&mut b, "dashboard-workers.png");
    b.navigate(&format!("{base}/jobs/{job}/samples/0"));
    b.wait_for(
        "[...document.querySelectorAll('.passes img')].every(i => i.complete && i.naturalWidth > 0)",
        "the sample's passes",
    );
    save(&mut b, "dashboard-sample.png");
}
