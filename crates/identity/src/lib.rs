//! Generated people: identity id *k* of a dataset is a new person, a pure function of the
//! identity's parameters (sampled by `lightfarm_scene` from (seed, k)) and the model data.

pub mod error;
pub mod eyes;
pub mod ict;
pub mod makehuman;
pub mod person;
pub mod skin;

pub use error::IdentityError;
