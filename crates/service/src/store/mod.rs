//! Durable state: the SQL database (scenes, jobs, job events, objects, embeddings) and the blob
//! store (scene files, checkpoints, results). All service state lives here, so API replicas and
//! worker processes stay stateless.

pub mod blob;
mod database;
mod error;
pub mod events;
pub mod jobs;
mod lease_reaping;
pub mod objects;
pub mod process_tag;
pub mod scenes;
pub mod tenancy;

pub use blob::{BlobError, BlobStore, LocalBlobStore};
pub use database::Database;
pub use error::StoreError;
pub use tenancy::{Caller, DEFAULT_TENANT};

/// Milliseconds since the Unix epoch, the one timestamp representation in the database.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|elapsed| elapsed.as_millis() as i64)
        .unwrap_or(0)
}
