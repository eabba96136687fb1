//! Blobs in an S3-compatible object store (`blobs.url = "s3://bucket/prefix"`), through the
//! `object_store` crate. Every write is one PUT or one completed multipart upload, so a reader
//! sees the old object or the new one, never half of one; files are streamed in parts, never held
//! whole in memory.
//!
//! The [`BlobStore`] methods block, as the trait asks. They run the client on this store's own
//! small runtime and wait for it, so they work from blocking threads (job steps,
//! `spawn_blocking`) and never need the caller's runtime.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use futures::{StreamExt, TryStreamExt};
use object_store::aws::AmazonS3Builder;
use object_store::buffered::BufWriter;
use object_store::path::Path as ObjectPath;
use object_store::{ClientOptions, ObjectStore, ObjectStoreExt, RetryConfig};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::blob::{BlobError, BlobStore, validate_key};
use crate::config::BlobsConfig;

/// Parts of a streamed upload; S3 needs at least 5 MiB for every part but the last.
const PART_BYTES: usize = 8 << 20;
/// Parts in flight at once: memory for a streamed upload stays about this many parts, whatever
/// the file's size.
const PARTS_IN_FLIGHT: usize = 3;
const READ_CHUNK: usize = 1 << 20;

pub struct ObjectBlobStore {
    store: Arc<dyn ObjectStore>,
    /// Key prefix inside the bucket (no leading or trailing `/`), empty for the bucket's root.
    prefix: String,
    /// Where the client's futures run; the blocking methods wait on them from any thread.
    /// Always `Some` until dropped.
    runtime: Option<tokio::runtime::Runtime>,
    /// `s3://bucket/prefix`, for messages.
    url: String,
}

impl std::fmt::Debug for ObjectBlobStore {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        formatter
            .debug_struct("ObjectBlobStore")
            .field("url", &self.url)
            .finish()
    }
}

impl ObjectBlobStore {
    /// Connects to the bucket `blobs.url` names. Credentials, region and endpoint come from the
    /// config when set, else from the standard `AWS_*` environment variables. Nothing is sent
    /// yet: an unreachable store shows on first use (and in `/readyz`).
    pub fn open(config: &BlobsConfig, url: &str) -> Result<Self, BlobError> {
        let invalid = |reason: &'static str| BlobError::InvalidKey {
            key: url.to_string(),
            reason,
        };
        let rest = url
            .strip_prefix("s3://")
            .ok_or_else(|| invalid("blobs.url must start with s3://"))?;
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        if bucket.is_empty() {
            return Err(invalid("blobs.url names no bucket"));
        }
        let prefix = prefix.trim_matches('/').to_string();
        if !prefix.is_empty() {
            validate_key(&prefix)?;
        }
        let mut builder = AmazonS3Builder::from_env()
            .with_bucket_name(bucket)
            .with_client_options(
                ClientOptions::new()
                    .with_allow_http(config.allow_http)
                    .with_timeout(Duration::from_secs_f64(config.request_timeout_secs))
                    .with_connect_timeout(Duration::from_secs_f64(
                        config.request_timeout_secs.min(5.0),
                    )),
            )
            .with_retry(RetryConfig {
                max_retries: config.max_retries as usize,
                retry_timeout: Duration::from_secs_f64(config.request_timeout_secs),
                ..RetryConfig::default()
            });
        if let Some(endpoint) = &config.endpoint {
            // Self-hosted servers (MinIO, s3rver, Ceph) answer path-style requests.
            builder = builder
                .with_endpoint(endpoint)
                .with_virtual_hosted_style_request(false);
        }
        if let Some(region) = &config.region {
            builder = builder.with_region(region);
        }
        if let Some(key) = &config.access_key_id {
            builder = builder.with_access_key_id(key);
        }
        if let Some(secret) = &config.secret_access_key {
            builder = builder.with_secret_access_key(secret);
        }
        let store = builder.build().map_err(|error| remote(url, error))?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("segsplat-blobs")
            .enable_all()
            .build()
            .map_err(|source| BlobError::Io {
                key: url.to_string(),
                source,
            })?;
        Ok(Self {
            store: Arc::new(store),
            prefix,
            runtime: Some(runtime),
            url: url.to_string(),
        })
    }

    /// Runs `future` on this store's runtime and waits for it.
    fn wait<T: Send + 'static>(
        &self,
        future: impl Future<Output = T> + Send + 'static,
    ) -> Result<T, BlobError> {
        let unavailable = |reason: String| BlobError::Unavailable {
            key: self.url.clone(),
            reason,
        };
        let runtime = self
            .runtime
            .as_ref()
            .ok_or_else(|| unavailable("the blob store is closed".into()))?;
        let task = runtime.spawn(future);
        futures::executor::block_on(task)
            .map_err(|error| unavailable(format!("the object-store client crashed: {error}")))
    }

    fn location(&self, key: &str) -> Result<ObjectPath, BlobError> {
        validate_key(key)?;
        let full = if self.prefix.is_empty() {
            key.to_string()
        } else {
            format!("{}/{key}", self.prefix)
        };
        ObjectPath::parse(&full).map_err(|_| BlobError::InvalidKey {
            key: key.to_string(),
            reason: "not a valid object path",
        })
    }

    /// The location of a prefix (which may end in `/`, or be empty for everything).
    fn prefix_location(&self, prefix: &str) -> Result<Option<ObjectPath>, BlobError> {
        let trimmed = prefix.trim_end_matches('/');
        if trimmed.is_empty() {
            return Ok((!self.prefix.is_empty()).then(|| ObjectPath::from(self.prefix.as_str())));
        }
        self.location(trimmed).map(Some)
    }

    /// Our key for a listed object (the store's prefix removed).
    fn key_of(&self, location: &ObjectPath) -> String {
        let full = location.as_ref();
        if self.prefix.is_empty() {
            return full.to_string();
        }
        full.strip_prefix(&self.prefix)
            .map(|rest| rest.trim_start_matches('/'))
            .unwrap_or(full)
            .to_string()
    }
}

impl Drop for ObjectBlobStore {
    fn drop(&mut self) {
        // The last handle may go away inside async code, where a blocking runtime shutdown
        // would panic.
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_background();
        }
    }
}

/// A failed request: the object store is down, refuses us, or the network is gone. The message
/// keeps the store's reason; callers answer 503.
fn remote(key: &str, error: object_store::Error) -> BlobError {
    match error {
        object_store::Error::NotFound { .. } => BlobError::NotFound {
            key: key.to_string(),
        },
        other => BlobError::Unavailable {
            key: key.to_string(),
            reason: other.to_string(),
        },
    }
}

impl BlobStore for ObjectBlobStore {
    fn put_bytes(&self, key: &str, bytes: &[u8]) -> Result<(), BlobError> {
        let location = self.location(key)?;
        let store = self.store.clone();
        let payload = bytes::Bytes::copy_from_slice(bytes);
        self.wait(async move { store.put(&location, payload.into()).await })?
            .map(|_| ())
            .map_err(|error| remote(key, error))
    }

    fn put_file(&self, key: &str, source: &Path) -> Result<(), BlobError> {
        let location = self.location(key)?;
        let store = self.store.clone();
        let source = source.to_path_buf();
        let owned_key = key.to_string();
        self.wait(async move {
            let mut input =
                tokio::fs::File::open(&source)
                    .await
                    .map_err(|source| BlobError::Io {
                        key: owned_key.clone(),
                        source,
                    })?;
            // Small files go up in one PUT; larger ones as a multipart upload that is only
            // visible once completed, and aborted on any error.
            let mut writer = BufWriter::with_capacity(store, location, PART_BYTES)
                .with_max_concurrency(PARTS_IN_FLIGHT);
            let unavailable = |error: std::io::Error| BlobError::Unavailable {
                key: owned_key.clone(),
                reason: error.to_string(),
            };
            let mut buffer = vec![0u8; READ_CHUNK];
            let copied: std::io::Result<()> = async {
                loop {
                    let read = input.read(&mut buffer).await?;
                    if read == 0 {
                        return Ok(());
                    }
                    writer.write_all(&buffer[..read]).await?;
                }
            }
            .await;
            if let Err(error) = copied {
                // Parts may be in the store: abort the multipart upload (a no-op while the
                // writer still buffers).
                let _ = writer.abort().await;
                return Err(unavailable(error));
            }
            // The final request: the one PUT, or the last part and the completion, which
            // aborts the multipart upload itself when it fails. The writer is shut down either
            // way and must not be aborted again: object_store's `BufWriter::abort` panics
            // ("Already shut down") after `shutdown`.
            writer.shutdown().await.map_err(unavailable)
        })?
    }

    fn get_bytes(&self, key: &str) -> Result<Vec<u8>, BlobError> {
        let location = self.location(key)?;
        let store = self.store.clone();
        self.wait(async move { store.get(&location).await?.bytes().await })?
            .map(|bytes| bytes.to_vec())
            .map_err(|error| remote(key, error))
    }

    fn get_to_path(&self, key: &str, destination: &Path) -> Result<(), BlobError> {
        let location = self.location(key)?;
        let store = self.store.clone();
        let destination = destination.to_path_buf();
        let owned_key = key.to_string();
        self.wait(async move {
            let io_error = |source| BlobError::Io {
                key: owned_key.clone(),
                source,
            };
            let parent = destination.parent().unwrap_or(Path::new("."));
            tokio::fs::create_dir_all(parent).await.map_err(io_error)?;
            // Streamed into a temporary sibling, renamed once whole.
            let temp = tempfile::NamedTempFile::new_in(parent).map_err(io_error)?;
            let mut output = tokio::fs::File::from_std(temp.reopen().map_err(io_error)?);
            let mut body = store
                .get(&location)
                .await
                .map_err(|error| remote(&owned_key, error))?
                .into_stream();
            while let Some(chunk) = body.next().await {
                let chunk = chunk.map_err(|error| remote(&owned_key, error))?;
                output.write_all(&chunk).await.map_err(io_error)?;
            }
            output.flush().await.map_err(io_error)?;
            drop(output);
            temp.persist(&destination)
                .map_err(|error| io_error(error.error))?;
            Ok(())
        })?
    }

    fn exists(&self, key: &str) -> Result<bool, BlobError> {
        let location = self.location(key)?;
        let store = self.store.clone();
        match self.wait(async move { store.head(&location).await })? {
            Ok(_) => Ok(true),
            Err(object_store::Error::NotFound { .. }) => Ok(false),
            Err(error) => Err(remote(key, error)),
        }
    }

    fn list_prefix(&self, prefix: &str) -> Result<Vec<String>, BlobError> {
        let location = self.prefix_location(prefix)?;
        let store = self.store.clone();
        let listed: Vec<ObjectPath> = self
            .wait(async move {
                store
                    .list(location.as_ref())
                    .map_ok(|meta| meta.location)
                    .try_collect()
                    .await
            })?
            .map_err(|error| remote(prefix, error))?;
        let mut keys: Vec<String> = listed.iter().map(|path| self.key_of(path)).collect();
        keys.sort();
        Ok(keys)
    }

    fn delete_prefix(&self, prefix: &str) -> Result<u64, BlobError> {
        let location = self.prefix_location(prefix)?;
        let store = self.store.clone();
        self.wait(async move {
            let listed = store.list(location.as_ref()).map_ok(|meta| meta.location);
            let deleted: Vec<ObjectPath> =
                store.delete_stream(listed.boxed()).try_collect().await?;
            Ok::<u64, object_store::Error>(deleted.len() as u64)
        })?
        .map_err(|error| remote(prefix, error))
    }
}
