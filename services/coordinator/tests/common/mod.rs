//! What the coordinator's test files share.
pub mod browser;
