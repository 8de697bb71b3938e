//! The coordinator: accepts dataset jobs, leases their samples to render workers, commits the
//! results exactly once into the sample store, and streams them to trainers.
//!
//! Layout: [`scheduler`] is the state machine (jobs, tasks, leases, workers) over sled;
//! [`service`] the gRPC handlers; [`server`] opening the data directory and serving;
//! [`metrics`] Prometheus and, on the same port, the web [`dashboard`] (over HTTPS by
//! [`tls_listener`] when the coordinator has TLS); [`error`] the one mapping to gRPC status
//! codes.

pub mod dashboard;
pub mod durability;
pub mod error;
pub mod metrics;
pub mod scheduler;
pub mod server;
pub mod service;
pub mod tls_listener;

pub use error::CoordError;
pub use server::{Coordinator, CoordinatorConfig};
