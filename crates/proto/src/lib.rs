//! The lightfarm wire protocol (`proto/lightfarm/v1`): messages, clients and servers.
//!
//! Only this crate's types cross the wire; services convert to and from their own types at
//! their edges.

#![allow(clippy::large_enum_variant, clippy::doc_overindented_list_items)]

pub mod v1 {
    tonic::include_proto!("lightfarm.v1");
}
