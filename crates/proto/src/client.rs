//! The client side every lightfarm program shares: a channel whose calls carry the bearer
//! token (plain HTTP/2 or TLS with a given CA), which errors are worth waiting out, and the
//! reassembly of the sample streams (`GetSample`, `StreamSamples`) into whole samples.

use std::path::Path;
use std::time::Duration;

use tonic::codegen::InterceptedService;
use tonic::metadata::{Ascii, MetadataValue};
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint};
use tonic::{Code, Request, Status};

use crate::v1 as pb;

/// Why a channel could not be set up; the message names the input and the fix.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ConnectError(String);

/// Adds `authorization: Bearer <token>` to every call.
#[derive(Clone)]
pub struct Auth(MetadataValue<Ascii>);

impl tonic::service::Interceptor for Auth {
    fn call(&mut self, mut req: Request<()>) -> Result<Request<()>, Status> {
        req.metadata_mut().insert("authorization", self.0.clone());
        Ok(req)
    }
}

/// A channel whose every call carries the bearer token; any generated client wraps it.
pub type AuthedChannel = InterceptedService<Channel, Auth>;

/// Connects lazily (the server may not be up yet) to `url` with bearer `token`; with `tls_ca`
/// the server's certificate must chain to that PEM file.
pub fn channel(
    url: &str,
    token: &str,
    tls_ca: Option<&Path>,
) -> Result<(Channel, Auth), ConnectError> {
    let mut endpoint = Endpoint::from_shared(url.to_string())
        .map_err(|_| {
            ConnectError(format!(
                "address `{url}` is not a URL like http://host:7070"
            ))
        })?
        .connect_timeout(Duration::from_secs(5))
        .tcp_keepalive(Some(Duration::from_secs(20)));
    if let Some(ca) = tls_ca {
        let pem = std::fs::read(ca)
            .map_err(|e| ConnectError(format!("--tls-ca {}: {e}", ca.display())))?;
        endpoint = endpoint
            .tls_config(ClientTlsConfig::new().ca_certificate(Certificate::from_pem(pem)))
            .map_err(|e| ConnectError(format!("TLS configuration with {}: {e}", ca.display())))?;
    }
    let value: MetadataValue<Ascii> = format!("Bearer {token}")
        .parse()
        .map_err(|_| ConnectError("the token must be printable ASCII".into()))?;
    Ok((endpoint.connect_lazy(), Auth(value)))
}

/// Errors worth waiting out: the server is restarting or the network is cut.
pub fn transient(status: &Status) -> bool {
    matches!(
        status.code(),
        Code::Unavailable
            | Code::DeadlineExceeded
            | Code::Unknown
            | Code::Cancelled
            | Code::Aborted
    )
}

/// Reassembles a `GetSample` / `StreamSamples` stream (per sample: its info, then its data
/// chunks) into whole samples.
#[derive(Default)]
pub struct SampleChunks {
    current: Option<(pb::SampleInfo, Vec<u8>)>,
}

impl SampleChunks {
    /// Feeds one chunk; returns the previous sample when this chunk starts the next one. A data
    /// chunk before any info breaks the protocol and is an error.
    pub fn push(
        &mut self,
        chunk: pb::SampleChunk,
    ) -> Result<Option<(pb::SampleInfo, Vec<u8>)>, String> {
        match chunk.kind {
            Some(pb::sample_chunk::Kind::Info(info)) => {
                Ok(self.current.replace((info, Vec::new())))
            }
            Some(pb::sample_chunk::Kind::Data(d)) => match self.current.as_mut() {
                Some((_, buf)) => {
                    buf.extend_from_slice(&d);
                    Ok(None)
                }
                None => Err("the coordinator sent sample data before the sample's info".into()),
            },
            None => Ok(None),
        }
    }

    /// The current sample once all `info.size` bytes of it have arrived: a follower of a job
    /// that is still rendering should not wait for the next sample's info to see this one.
    pub fn take_complete(&mut self) -> Option<(pb::SampleInfo, Vec<u8>)> {
        match &self.current {
            Some((info, data)) if data.len() as u64 == info.size => self.current.take(),
            _ => None,
        }
    }

    /// The last sample, once the stream has ended.
    pub fn finish(self) -> Option<(pb::SampleInfo, Vec<u8>)> {
        self.current
    }
}
