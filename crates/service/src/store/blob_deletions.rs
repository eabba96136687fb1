//! Blob prefixes that must go but could not when that was decided: a failed upload's files while
//! the blob store was down. Each is recorded durably in `blob_deletions`,
//! in the database the scenes live in, and [`sweep_blob_deletions`] removes the files and then the
//! record once the store takes the deletion: at start and every [`SWEEP_EVERY`]
//! ([`run_blob_deletion_sweeps`], started with the service), so nothing stays in the bucket after
//! an outage, not even across a restart.

use std::sync::Arc;
use std::time::Duration;

use tokio_util::sync::CancellationToken;

use super::sql::query;
use super::{BlobError, BlobStore, Database, StoreError, now_ms};

/// At most this many prefixes are tried in one sweep.
const SWEEP_BATCH: i64 = 100;
/// How often the recorded prefixes are tried.
pub const SWEEP_EVERY: Duration = Duration::from_secs(5);

impl Database {
    /// Records that everything under `prefix` must be removed (again, if already recorded).
    pub async fn record_blob_deletion(&self, prefix: &str, reason: &str) -> Result<(), StoreError> {
        query(
            "INSERT INTO blob_deletions (prefix, reason, recorded_at_ms, last_error) \
             VALUES (?, ?, ?, NULL) ON CONFLICT (prefix) DO NOTHING",
        )
        .bind(prefix)
        .bind(reason)
        .bind(now_ms())
        .execute(self.sql())
        .await?;
        Ok(())
    }

    /// Prefixes waiting to be removed, oldest first.
    pub async fn pending_blob_deletions(&self) -> Result<Vec<String>, StoreError> {
        let rows =
            query("SELECT prefix FROM blob_deletions ORDER BY recorded_at_ms, prefix LIMIT ?")
                .bind(SWEEP_BATCH)
                .fetch_all(self.sql())
                .await?;
        rows.iter().map(|row| Ok(row.try_get("prefix")?)).collect()
    }

    async fn forget_blob_deletion(&self, prefix: &str) -> Result<(), StoreError> {
        query("DELETE FROM blob_deletions WHERE prefix = ?")
            .bind(prefix)
            .execute(self.sql())
            .await?;
        Ok(())
    }

    async fn note_blob_deletion_error(&self, prefix: &str, error: &str) -> Result<(), StoreError> {
        query("UPDATE blob_deletions SET last_error = ? WHERE prefix = ?")
            .bind(error)
            .bind(prefix)
            .execute(self.sql())
            .await?;
        Ok(())
    }
}

/// Removes everything under `prefix`, or, when the store cannot take it now, records it for
/// [`sweep_blob_deletions`]. Errors are logged: the caller is already failing for another reason.
pub async fn remove_or_record(
    database: &Database,
    blobs: &Arc<dyn BlobStore>,
    prefix: &str,
    reason: &str,
) {
    match delete_prefix(blobs, prefix).await {
        Ok(_) => {}
        Err(error) => {
            tracing::warn!(%error, %prefix, "cannot remove blobs now; recorded for the sweep");
            let recorded = database.record_blob_deletion(prefix, reason).await;
            if let Err(record_error) = recorded {
                tracing::error!(%record_error, %error, %prefix,
                    "cannot remove blobs nor record their removal; they stay in the store");
            }
        }
    }
}

/// Removes the recorded prefixes the store takes now and forgets them; returns how many are left.
pub async fn sweep_blob_deletions(
    database: &Database,
    blobs: &Arc<dyn BlobStore>,
) -> Result<usize, StoreError> {
    let mut left = 0;
    for prefix in database.pending_blob_deletions().await? {
        match delete_prefix(blobs, &prefix).await {
            Ok(removed) => {
                tracing::info!(%prefix, removed, "removed recorded blobs");
                database.forget_blob_deletion(&prefix).await?;
            }
            Err(error) => {
                left += 1;
                database
                    .note_blob_deletion_error(&prefix, &error.to_string())
                    .await?;
            }
        }
    }
    Ok(left)
}

async fn delete_prefix(blobs: &Arc<dyn BlobStore>, prefix: &str) -> Result<u64, BlobError> {
    let blobs = blobs.clone();
    let owned = prefix.to_string();
    tokio::task::spawn_blocking(move || blobs.delete_prefix(&owned))
        .await
        .map_err(|error| BlobError::Unavailable {
            key: prefix.to_string(),
            reason: format!("deleting crashed: {error}"),
        })?
}

/// Sweeps at once (what a previous life of the process left), then every [`SWEEP_EVERY`] until
/// `shutdown`. With nothing recorded a sweep is one small query.
pub async fn run_blob_deletion_sweeps(
    database: Database,
    blobs: Arc<dyn BlobStore>,
    shutdown: CancellationToken,
) {
    loop {
        match sweep_blob_deletions(&database, &blobs).await {
            Ok(0) => {}
            Ok(left) => tracing::warn!(left, "recorded blobs still cannot be removed"),
            Err(error) => tracing::warn!(%error, "cannot sweep the recorded blob deletions"),
        }
        tokio::select! {
            _ = tokio::time::sleep(SWEEP_EVERY) => {}
            _ = shutdown.cancelled() => return,
        }
    }
}
