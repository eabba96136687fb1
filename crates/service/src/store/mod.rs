//! Durable state: the SQL database (scenes, jobs, job events, objects, embeddings) and the blob
//! store (scene files, checkpoints, results). All service state lives here, so API replicas and
//! worker processes stay stateless.

pub mod blob;
pub mod blob_deletions;
mod database;
mod error;
pub mod events;
pub mod jobs;
mod lease_reaping;
pub mod object_blob;
pub mod objects;
pub mod process_tag;
pub mod scenes;
mod sql;
pub mod tenancy;
pub mod wakeups;
pub mod workers;

pub use blob::{BlobError, BlobStore, LocalBlobStore};
pub use database::{Backend, Database};
pub use error::StoreError;
pub use object_blob::ObjectBlobStore;
pub use tenancy::{Caller, DEFAULT_TENANT};

/// The blob store the config names: the S3-compatible bucket of `blobs.url`, else the local
/// directory under the data dir.
pub fn open_blob_store(
    config: &crate::config::Config,
) -> Result<std::sync::Arc<dyn BlobStore>, BlobError> {
    Ok(match &config.blobs.url {
        Some(url) => std::sync::Arc::new(ObjectBlobStore::open(&config.blobs, url)?),
        None => std::sync::Arc::new(LocalBlobStore::open(&config.blob_dir())?),
    })
}

/// Milliseconds since the Unix epoch, the one timestamp representation in the database.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|elapsed| elapsed.as_millis() as i64)
        .unwrap_or(0)
}
