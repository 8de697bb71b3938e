//! The coordinator: accepts dataset jobs, leases their samples to render workers, commits the
//! results exactly once into the sample store, and streams them to trainers.
//!
//! Layout: [`scheduler`] is the state machine (jobs, tasks, leases, workers) over sled;
//! [`service`] the gRPC handlers; [`server`] opening the data directory and serving;
//! [`metrics`] Prometheus and, on the same port, the web [`dashboard`]; [`error`] the one
//! mapping to gRPC status codes.

pub mod dashboard;
pub mod durability;
pub mod error;
pub mod metrics;
pub mod scheduler;
pub mod server;
pub mod service;

pub use error::CoordError;
pub use server::{Coordinator, CoordinatorConfig};
