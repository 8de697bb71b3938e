//! Who may see the dashboard: the coordinator's bearer token, typed once into the login page,
//! buys a session. The session id lives only in an HTTP-only, SameSite=Strict cookie (Secure
//! when the coordinator serves TLS); each session has its own CSRF token, which every form that
//! changes something carries and every such request must echo.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Redirect, Response};
use subtle::ConstantTimeEq;

use super::App;

/// The cookie that holds the session id.
pub const COOKIE: &str = "lightfarm_session";

/// How long a session lasts without being used.
const IDLE: Duration = Duration::from_secs(12 * 3600);
/// Wrong tokens accepted per window before logins pause until the window ends: guessing a
/// token stays hopeless however many clients try, and a typo never locks anyone out for long.
const WRONG_PER_WINDOW: u32 = 10;
const WINDOW: Duration = Duration::from_secs(60);

#[derive(Clone, Debug)]
pub struct Session {
    pub csrf: String,
    last_used: Instant,
}

/// The session of a request for a page; a request without one is sent to `/login`.
pub struct PageSession(pub Session);

/// The session of a request for a fragment, a file or the JSON API, which the pages' scripts
/// fetch; a request without one gets 401 (a login page has no place inside a table cell).
pub struct ApiSession(pub Session);

impl FromRequestParts<App> for PageSession {
    type Rejection = Response;

    async fn from_request_parts(parts: &mut Parts, app: &App) -> Result<Self, Response> {
        match app.sessions.get(&parts.headers) {
            Some(s) => Ok(PageSession(s)),
            None => Err(Redirect::to("/login").into_response()),
        }
    }
}

impl FromRequestParts<App> for ApiSession {
    type Rejection = Response;

    async fn from_request_parts(parts: &mut Parts, app: &App) -> Result<Self, Response> {
        match app.sessions.get(&parts.headers) {
            Some(s) => Ok(ApiSession(s)),
            None => Err((StatusCode::UNAUTHORIZED, "log in on /login").into_response()),
        }
    }
}

/// Sessions in memory: a coordinator restart logs everyone out, which costs a login and
/// keeps no secret on disk.
pub struct Sessions {
    token: Vec<u8>,
    secure: bool,
    live: Mutex<HashMap<String, Session>>,
    /// (start of the current window, wrong tokens in it).
    wrong: Mutex<(Instant, u32)>,
}

/// What a login attempt gets.
#[derive(Debug, PartialEq, Eq)]
pub enum Login {
    Right,
    Wrong,
    /// Too many wrong tokens lately: try again after this many seconds.
    Paused(u64),
}

/// 32 random bytes as hex; None when the operating system has no randomness to give.
fn random_id() -> Option<String> {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes).ok()?;
    Some(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

impl Sessions {
    pub fn new(token: &str, secure: bool) -> Sessions {
        Sessions {
            token: token.as_bytes().to_vec(),
            secure,
            live: Mutex::new(HashMap::new()),
            wrong: Mutex::new((Instant::now(), 0)),
        }
    }

    /// Checks a login's token, counting wrong ones against the window's budget (while the
    /// budget is spent, even the right token waits: an attacker learns nothing from it).
    pub fn login(&self, given: &str) -> Login {
        let mut wrong = self.wrong.lock().unwrap_or_else(|p| p.into_inner());
        if wrong.0.elapsed() >= WINDOW {
            *wrong = (Instant::now(), 0);
        }
        if wrong.1 >= WRONG_PER_WINDOW {
            return Login::Paused(WINDOW.saturating_sub(wrong.0.elapsed()).as_secs() + 1);
        }
        if self.token_matches(given) {
            Login::Right
        } else {
            wrong.1 += 1;
            Login::Wrong
        }
    }

    /// Whether `given` is the coordinator's token (in constant time).
    pub fn token_matches(&self, given: &str) -> bool {
        !self.token.is_empty() && bool::from(self.token.as_slice().ct_eq(given.as_bytes()))
    }

    /// A new session and the `Set-Cookie` value that hands it to the browser.
    pub fn open(&self) -> Option<(Session, String)> {
        let (id, csrf) = (random_id()?, random_id()?);
        let session = Session {
            csrf,
            last_used: Instant::now(),
        };
        let mut live = self.live.lock().unwrap_or_else(|p| p.into_inner());
        live.retain(|_, s| s.last_used.elapsed() < IDLE);
        live.insert(id.clone(), session.clone());
        let secure = if self.secure { "; Secure" } else { "" };
        Some((
            session,
            format!("{COOKIE}={id}; Path=/; HttpOnly; SameSite=Strict{secure}"),
        ))
    }

    /// The session of a request's cookie, if it is live.
    pub fn get(&self, headers: &HeaderMap) -> Option<Session> {
        let id = cookie(headers)?;
        let mut live = self.live.lock().unwrap_or_else(|p| p.into_inner());
        let s = live.get_mut(&id)?;
        if s.last_used.elapsed() >= IDLE {
            live.remove(&id);
            return None;
        }
        s.last_used = Instant::now();
        Some(s.clone())
    }

    /// Ends the request's session; the `Set-Cookie` value that clears the cookie.
    pub fn close(&self, headers: &HeaderMap) -> String {
        if let Some(id) = cookie(headers) {
            self.live
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .remove(&id);
        }
        format!("{COOKIE}=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0")
    }
}

impl Session {
    /// Whether a form's CSRF field is this session's (in constant time).
    pub fn csrf_matches(&self, given: &str) -> bool {
        bool::from(self.csrf.as_bytes().ct_eq(given.as_bytes()))
    }
}

/// The session id in the request's `Cookie` headers.
fn cookie(headers: &HeaderMap) -> Option<String> {
    headers
        .get_all(axum::http::header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|kv| kv.trim().split_once('='))
        .find(|(k, _)| *k == COOKIE)
        .map(|(_, v)| v.to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_session_is_found_by_its_cookie_and_closed() {
        let s = Sessions::new("tok", false);
        assert!(s.token_matches("tok") && !s.token_matches("tok ") && !s.token_matches(""));
        let (session, set) = s.open().expect("randomness");
        assert!(set.contains("HttpOnly") && set.contains("SameSite=Strict"));
        assert!(!set.contains("Secure"));
        let id = set
            .split(';')
            .next()
            .and_then(|kv| kv.split_once('='))
            .map(|(_, v)| v.to_owned())
            .expect("id");
        let mut headers = HeaderMap::new();
        headers.insert(
            axum::http::header::COOKIE,
            format!("other=1; {COOKIE}={id}").parse().expect("header"),
        );
        let got = s.get(&headers).expect("live");
        assert!(got.csrf_matches(&session.csrf) && !got.csrf_matches("guess"));
        s.close(&headers);
        assert!(s.get(&headers).is_none());
        let s = Sessions::new("tok", false);
        for _ in 0..WRONG_PER_WINDOW {
            assert_eq!(s.login("guess"), Login::Wrong);
        }
        assert!(matches!(s.login("tok"), Login::Paused(n) if (1..=61).contains(&n)));
        assert!(Sessions::new("t", true)
            .open()
            .expect("id")
            .1
            .contains("; Secure"));
    }
}
