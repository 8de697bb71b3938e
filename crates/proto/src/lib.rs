//! The lightfarm wire protocol (`proto/lightfarm/v1`): messages, clients and servers.
//!
//! Only this crate's types cross the wire; services convert to and from their own types at
//! their edges.

#![allow(clippy::large_enum_variant, clippy::doc_overindented_list_items)]

pub mod v1 {
    tonic::include_proto!("lightfarm.v1");
}

pub mod client;

/// The version of the protocol in `proto/lightfarm/v1`, answered by `Jobs.GetServerInfo`.
/// Bump it with any change a client must know of, together with the Python client's
/// `clients/python/lightfarm/_protocol.py` (a test checks they agree).
pub const PROTOCOL_VERSION: u32 = 1;

/// Bearer-token checking shared by every lightfarm service.
pub mod auth {
    use tonic::{Request, Status};

    /// An interceptor that accepts requests carrying `authorization: Bearer <token>`;
    /// `service` names where the token is configured, for the error a client sees.
    pub fn bearer(
        token: &str,
        service: &'static str,
    ) -> impl Fn(Request<()>) -> Result<Request<()>, Status> + Clone + Send + Sync + 'static {
        let expected = format!("Bearer {token}");
        move |req: Request<()>| match req
            .metadata()
            .get("authorization")
            .and_then(|v| v.to_str().ok())
        {
            Some(v) if constant_time_eq(v.as_bytes(), expected.as_bytes()) => Ok(req),
            Some(_) => Err(Status::unauthenticated(format!(
                "wrong bearer token: use the {service}'s --token / LIGHTFARM_TOKEN"
            ))),
            None => Err(Status::unauthenticated(
                "missing bearer token: pass --token or set LIGHTFARM_TOKEN",
            )),
        }
    }

    /// Token comparison that does not stop at the first differing byte.
    fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
        a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
    }
}
