//! Headless Chromium driven over the Chrome DevTools Protocol, for the dashboard tests: a
//! page that navigates, runs JavaScript and answers with JSON values, and screenshots. The
//! browser is Debian's `chromium` (scripts/setup-system.sh installs it); without it the tests
//! skip with the install command, except under CI (`CI` set and not "false"), where they fail.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use tungstenite::{Message, WebSocket};

pub struct Browser {
    child: Child,
    _profile: tempfile::TempDir,
    ws: WebSocket<TcpStream>,
    next_id: u64,
}

fn ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false")
}

/// `chromium` on PATH, or None (then the caller skips, outside CI).
pub fn find() -> Option<PathBuf> {
    let found = ["chromium", "chromium-browser"].iter().find_map(|name| {
        std::env::var_os("PATH")?
            .to_str()?
            .split(':')
            .map(|d| PathBuf::from(d).join(name))
            .find(|p| p.is_file())
    });
    if found.is_none() {
        assert!(
            !ci(),
            "chromium is needed for the dashboard's browser tests under CI: apt-get install chromium"
        );
        eprintln!("skipping: no chromium (apt-get install chromium, or ./scripts/test.sh as root)");
    }
    found
}

/// A plain HTTP GET of the DevTools endpoint (which keeps the connection open: the body is
/// read by its Content-Length).
fn devtools_get(port: u16, path: &str) -> Option<String> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(10))).ok()?;
    write!(s, "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").ok()?;
    let mut buf = Vec::new();
    let mut chunk = [0u8; 8192];
    loop {
        let n = s.read(&mut chunk).ok()?;
        if n == 0 {
            return None;
        }
        buf.extend_from_slice(&chunk[..n]);
        let text = String::from_utf8_lossy(&buf).into_owned();
        if let Some((head, body)) = text.split_once("\r\n\r\n") {
            let len: usize = head
                .lines()
                .filter_map(|l| l.split_once(':'))
                .find(|(k, _)| k.trim().eq_ignore_ascii_case("content-length"))
                .and_then(|(_, v)| v.trim().parse().ok())?;
            if body.len() >= len {
                return Some(body[..len].to_owned());
            }
        }
    }
}

impl Browser {
    pub fn launch(chromium: &PathBuf) -> Browser {
        let profile = tempfile::tempdir().expect("profile dir");
        let child = Command::new(chromium)
            .args([
                "--headless=new",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--disable-extensions",
                "--remote-debugging-port=0",
                "--window-size=1100,800",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start chromium");
        let port_file = profile.path().join("DevToolsActivePort");
        let started = Instant::now();
        let port: u16 = loop {
            if let Some(p) = std::fs::read_to_string(&port_file)
                .ok()
                .and_then(|t| t.lines().next().and_then(|l| l.parse().ok()))
            {
                break p;
            }
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "chromium did not start"
            );
            std::thread::sleep(Duration::from_millis(100));
        };
        let url = loop {
            let pages: Value = devtools_get(port, "/json/list")
                .and_then(|b| serde_json::from_str(&b).ok())
                .unwrap_or(Value::Null);
            if let Some(u) = pages.as_array().and_then(|a| {
                a.iter()
                    .find(|p| p["type"] == "page")
                    .and_then(|p| p["webSocketDebuggerUrl"].as_str())
                    .map(str::to_owned)
            }) {
                break u;
            }
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "no page target"
            );
            std::thread::sleep(Duration::from_millis(100));
        };
        let stream = TcpStream::connect(("127.0.0.1", port)).expect("DevTools port");
        // A browser that stops answering fails the test instead of hanging it.
        stream
            .set_read_timeout(Some(Duration::from_secs(60)))
            .expect("timeout");
        let (ws, _) = tungstenite::client(url.as_str(), stream).expect("DevTools websocket");
        let mut b = Browser {
            child,
            _profile: profile,
            ws,
            next_id: 0,
        };
        b.call("Page.enable", json!({}));
        // The window size includes the browser's own UI; fix the page's viewport instead.
        b.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": 1100, "height": 800, "deviceScaleFactor": 1, "mobile": false}),
        );
        b
    }

    /// Sends a command and returns its result (events in between are dropped).
    pub fn call(&mut self, method: &str, params: Value) -> Value {
        match self.try_call(method, params) {
            Ok(v) => v,
            Err(e) => panic!("{method}: {e}"),
        }
    }

    /// [`Browser::call`] that hands DevTools' error reply back instead of failing the test.
    fn try_call(&mut self, method: &str, params: Value) -> Result<Value, Value> {
        self.next_id += 1;
        let id = self.next_id;
        let msg = json!({"id": id, "method": method, "params": params}).to_string();
        self.ws.send(Message::text(msg)).expect("send");
        loop {
            let Message::Text(t) = self.ws.read().expect("read") else {
                continue;
            };
            let v: Value = serde_json::from_str(t.as_str()).expect("json");
            if v["id"] == id {
                return match v.get("error") {
                    Some(_) => Err(v),
                    None => Ok(v["result"].clone()),
                };
            }
        }
    }

    pub fn navigate(&mut self, url: &str) {
        self.call("Page.navigate", json!({ "url": url }));
        self.wait_for("document.readyState === 'complete'", "the page to load");
    }

    /// The value of a JavaScript expression in the page.
    pub fn eval(&mut self, expr: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            json!({"expression": expr, "returnByValue": true, "awaitPromise": true}),
        );
        assert!(r.get("exceptionDetails").is_none(), "{expr}: {r}");
        r["result"]["value"].clone()
    }

    /// Polls `expr` until it is true (page loads and the dashboard's refresh included).
    pub fn wait_for(&mut self, expr: &str, what: &str) {
        self.wait_for_long(expr, what, Duration::from_secs(30));
    }

    /// [`Browser::wait_for`] with a time limit of its own (renders on a busy CI machine).
    pub fn wait_for_long(&mut self, expr: &str, what: &str, limit: Duration) {
        let started = Instant::now();
        let guarded =
            format!("(() => {{ try {{ return !!({expr}); }} catch (e) {{ return false; }} }})()");
        while !self.poll(&guarded) {
            assert!(
                started.elapsed() < limit,
                "waited {limit:?} for {what} ({expr}); page: {}",
                self.eval("document.body ? document.body.innerText : ''")
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// One evaluation of a guarded predicate. A form submit or a redirect can replace the
    /// page while the evaluation is in flight; DevTools then answers "Inspected target
    /// navigated or closed", which means "not yet" to a poll, not a failure.
    fn poll(&mut self, guarded: &str) -> bool {
        let params = json!({"expression": guarded, "returnByValue": true, "awaitPromise": true});
        match self.try_call("Runtime.evaluate", params) {
            Ok(r) => r["result"]["value"] == Value::Bool(true),
            Err(e) if e.to_string().contains("navigated or closed") => false,
            Err(e) => panic!("Runtime.evaluate: {e}"),
        }
    }

    /// The viewport as PNG bytes.
    pub fn screenshot(&mut self) -> Vec<u8> {
        use base64::Engine;
        let r = self.call("Page.captureScreenshot", json!({"format": "png"}));
        base64::engine::general_purpose::STANDARD
            .decode(r["data"].as_str().expect("data"))
            .expect("base64")
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
