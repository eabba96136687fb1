//! The second half of an upload, once the archive is on disk: ingest it and record the scene.
//!
//! It runs as its own task, not inside the request's future: hyper drops a handler's future
//! when the client disconnects, and a dropped future would leave the blocking ingest writing
//! files that no scene row ever points at. The task always ends with either a recorded scene or
//! nothing of the upload left in the blob store, whether or not anyone still waits for it.

use tempfile::NamedTempFile;

use super::error::{ApiError, ApiResult};
use super::state::AppState;
use segsplat_scene::{InputErrorClass, LoadOptions, PixelLimits, UnpackLimits};
use segsplat_service::store::now_ms;
use segsplat_service::store::scenes::SceneRecord;
use segsplat_service::usecases::ingest::{IngestRequest, ingest_scene};

/// Ingests `archive` as a new scene of `tenant` named `name` (the scene id when `None`) in a
/// detached task and waits for it; the task finishes even when this future is dropped.
pub async fn ingest_and_record(
    state: AppState,
    archive: NamedTempFile,
    name: Option<String>,
    tenant: String,
) -> ApiResult<SceneRecord> {
    tokio::spawn(run(state, archive, name, tenant))
        .await
        .map_err(|error| ApiError::internal(format!("scene ingest crashed: {error}")))?
}

async fn run(
    state: AppState,
    archive: NamedTempFile,
    name: Option<String>,
    tenant: String,
) -> ApiResult<SceneRecord> {
    let config = &state.config;
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
        blobs: state.blobs.clone(),
        blob_prefix: blob_prefix.clone(),
    };
    let summary = tokio::task::spawn_blocking(move || ingest_scene(&ingest))
        .await
        .map_err(|error| ApiError::internal(format!("scene ingest crashed: {error}")))?
        .map_err(|error| {
            metrics::counter!("segsplat_scene_uploads_total", "outcome" => "rejected").increment(1);
            match error.class() {
                // The details name server paths; they go to the log, not to the client.
                InputErrorClass::Internal => {
                    tracing::error!(%error, %scene_id, "storing an upload failed");
                    ApiError::internal(format!(
                        "the server could not store the upload (its log has the details under \
                         upload {scene_id})"
                    ))
                }
                class => ApiError::from_input_class(class, error.to_string()),
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
    if let Err(error) = state.database.insert_scene(&record).await {
        let blobs = state.blobs.clone();
        let _ = tokio::task::spawn_blocking(move || blobs.delete_prefix(&blob_prefix)).await;
        return Err(error.into());
    }
    metrics::counter!("segsplat_scene_uploads_total", "outcome" => "stored").increment(1);
    tracing::info!(scene_id = %record.id, frames = record.summary.frame_count, "scene stored");
    Ok(record)
}
