//! The durable half of the lightfarm coordinator's data: content-addressed blobs (sample EXRs
//! and assets), the sled index of committed samples, and export of committed samples to
//! WebDataset tar shards or a folder, and the one reader of a sample EXR's passes and header. See README.md for what is deliberately not here.

mod blob;
mod disk;
mod error;
mod export;
mod index;
mod memory;
mod sample_exr;
mod tiered;

pub use blob::{hash_hex, is_hash, BlobStore, BlobWriter, Hash};
pub use disk::DiskBlobStore;
pub use error::StoreError;
pub use export::{
    export, list_export_folder, read_export, ExportEntry, ExportFormat, ExportReport, ExportWriter,
    ExportedSample,
};
pub use index::{CommitOutcome, SampleIndex, SampleRecord};
pub use memory::MemoryBlobStore;
pub use sample_exr::{ExrLayer, SAMPLE_ATTRIBUTE};
pub use tiered::{TieredBlobStore, DEFAULT_INLINE_MAX};
