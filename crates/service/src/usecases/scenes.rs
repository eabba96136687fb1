//! Scenes: record an uploaded archive as a scene, look scenes up, list and delete them. The one
//! implementation behind REST `/v1/scenes` and gRPC `GetScene` / `ListScenes`.
//!
//! Creating a scene runs as its own task, not inside the caller's future: an HTTP server drops a
//! handler's future when the client disconnects, and a dropped future would leave the blocking
//! ingest writing files that no scene row ever points at. The task always ends with either a
//! recorded scene or nothing of the upload left in the blob store, whether or not anyone still
//! waits for it: files the store cannot delete at that moment (it is down) are recorded in the
//! database and removed by the sweep once it is back (`store::blob_deletions`).

use tempfile::NamedTempFile;

use segsplat_scene::{InputErrorClass, LoadOptions, PixelLimits, UnpackLimits};

use super::ingest::{IngestError, IngestRequest, ingest_scene};
use crate::core::ServiceCore;
use crate::store::blob_deletions::remove_or_record;
use crate::store::scenes::{DeleteSceneError, SceneRecord};
use crate::store::{BlobError, Caller, StoreError, now_ms};

/// Why a failed upload's files are removed, as recorded when the store cannot take it at once.
const FAILED_UPLOAD: &str = "a failed upload";

#[derive(Debug, thiserror::Error)]
pub enum SceneFailure {
    #[error("scene {0} not found")]
    NotFound(String),
    /// The upload is not a dataset this service takes; `class` says how.
    #[error("{message}")]
    Rejected {
        class: InputErrorClass,
        message: String,
    },
    #[error("scene {scene_id} has {active_jobs} queued or running job(s); cancel them first")]
    Busy { scene_id: String, active_jobs: i64 },
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Blob(#[from] BlobError),
    /// The server failed; the message names no server path.
    #[error("{0}")]
    Internal(String),
}

/// Ingests `archive` as a new scene of `tenant` named `name` (the scene id when `None`) in a
/// detached task and waits for it; the task finishes even when this future is dropped.
pub async fn create_scene(
    core: &ServiceCore,
    archive: NamedTempFile,
    name: Option<String>,
    tenant: String,
) -> Result<SceneRecord, SceneFailure> {
    tokio::spawn(ingest_and_record(core.clone(), archive, name, tenant))
        .await
        .map_err(|error| SceneFailure::Internal(format!("scene ingest crashed: {error}")))?
}

async fn ingest_and_record(
    core: ServiceCore,
    archive: NamedTempFile,
    name: Option<String>,
    tenant: String,
) -> Result<SceneRecord, SceneFailure> {
    let config = &core.config;
    let scene_id = uuid::Uuid::now_v7().to_string();
    let blob_prefix = format!("scenes/{scene_id}");
    let ingest = IngestRequest {
        archive: archive.path().to_path_buf(),
        scratch_dir: config.scratch_dir(),
        limits: UnpackLimits {
            max_unpacked_bytes: config.limits.max_unpacked_bytes,
            max_files: config.limits.max_files,
        },
        load_options: LoadOptions {
            background: config.scene.background,
            video_frames: config.scene.video_frames.clone(),
            ..LoadOptions::default()
        },
        pixel_limits: PixelLimits {
            max_image_pixels: config.limits.max_image_pixels,
            max_total_pixels: config.limits.max_total_pixels,
        },
        blobs: core.blobs.clone(),
        blob_prefix: blob_prefix.clone(),
    };
    let ingested = tokio::task::spawn_blocking(move || ingest_scene(&ingest))
        .await
        .map_err(|error| SceneFailure::Internal(format!("scene ingest crashed: {error}")))?;
    if ingested.is_err() {
        remove_or_record(&core.database, &core.blobs, &blob_prefix, FAILED_UPLOAD).await;
    }
    let summary = ingested.map_err(|error| {
        metrics::counter!("segsplat_scene_uploads_total", "outcome" => "rejected").increment(1);
        if let IngestError::Blob(blob @ BlobError::Unavailable { .. }) = error {
            return SceneFailure::Blob(blob);
        }
        match error.class() {
            // The details name server paths; they go to the log, not to the client.
            InputErrorClass::Internal => {
                tracing::error!(%error, %scene_id, "storing an upload failed");
                SceneFailure::Internal(format!(
                    "the server could not store the upload (its log has the details under \
                         upload {scene_id})"
                ))
            }
            class => SceneFailure::Rejected {
                class,
                message: error.client_message(),
            },
        }
    })?;
    drop(archive);

    let record = SceneRecord {
        name: name.unwrap_or_else(|| scene_id.clone()),
        id: scene_id,
        summary,
        blob_prefix: blob_prefix.clone(),
        created_at_ms: now_ms(),
        tenant,
    };
    if let Err(error) = core.database.insert_scene(&record).await {
        // With the database down the record of the removal may not land either; then the
        // files stay, as the log says.
        remove_or_record(&core.database, &core.blobs, &blob_prefix, FAILED_UPLOAD).await;
        return Err(error.into());
    }
    metrics::counter!("segsplat_scene_uploads_total", "outcome" => "stored").increment(1);
    tracing::info!(scene_id = %record.id, frames = record.summary.frame_count, "scene stored");
    Ok(record)
}

/// The scene, if the caller may see it.
pub async fn get_scene(
    core: &ServiceCore,
    caller: &Caller,
    scene_id: &str,
) -> Result<SceneRecord, SceneFailure> {
    core.database
        .get_scene(scene_id, caller)
        .await?
        .ok_or_else(|| SceneFailure::NotFound(scene_id.to_string()))
}

/// The caller's tenant's scenes (every tenant's for an admin), oldest first.
pub async fn list_scenes(
    core: &ServiceCore,
    caller: &Caller,
) -> Result<Vec<SceneRecord>, SceneFailure> {
    Ok(core.database.list_scenes(caller).await?)
}

/// Deletes a scene, its jobs, objects and files; refused while one of its jobs is queued or
/// running.
pub async fn delete_scene(
    core: &ServiceCore,
    caller: &Caller,
    scene_id: &str,
) -> Result<(), SceneFailure> {
    let (record, job_ids) =
        core.database
            .delete_scene(scene_id, caller)
            .await
            .map_err(|error| match error {
                DeleteSceneError::NotFound(id) => SceneFailure::NotFound(id),
                DeleteSceneError::Busy {
                    scene_id,
                    active_jobs,
                } => SceneFailure::Busy {
                    scene_id,
                    active_jobs,
                },
                DeleteSceneError::Store(store) => SceneFailure::Store(store),
            })?;
    let blobs = core.blobs.clone();
    tokio::task::spawn_blocking(move || {
        blobs.delete_prefix(&record.blob_prefix)?;
        for job_id in job_ids {
            blobs.delete_prefix(&format!("jobs/{job_id}"))?;
        }
        Ok::<(), BlobError>(())
    })
    .await
    .map_err(|error| SceneFailure::Internal(format!("deleting scene files crashed: {error}")))??;
    Ok(())
}
