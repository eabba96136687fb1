//! Downloads of a scene's trained version: the whole scene (`scene.ply`, or compressed
//! `scene.spz`; for a dynamic scene also moved to a time with `?time=`), the labels sidecar
//! (`labels.npy`, object ids per Gaussian in PLY order), cameras and reports, and single objects
//! as their own PLY or SPZ.

use axum::Extension;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};

use serde::Deserialize;
use utoipa::IntoParams;

use super::error::{ApiError, ApiResult, ErrorBody};
use super::extract::{Query, UrlPath};
use super::params::{parse_level, parse_time};
use super::schema_names::{BinaryFile, LevelName, TimeValue};
use super::state::AppState;
use segsplat_method::scene_files::SCENE_FILE;
use segsplat_service::serving::SplatFormat;
use segsplat_service::store::Caller;
use segsplat_service::usecases::serving::SPZ_FILE;

fn content_type(file: &str) -> &'static str {
    if file.ends_with(".json") {
        "application/json"
    } else {
        "application/octet-stream"
    }
}

fn attachment_headers(name: &str, content_type: &str) -> [(header::HeaderName, String); 2] {
    [
        (header::CONTENT_TYPE, content_type.to_string()),
        (
            header::CONTENT_DISPOSITION,
            format!("attachment; filename=\"{name}\""),
        ),
    ]
}

fn attachment(name: &str, content_type: &'static str, bytes: Vec<u8>) -> Response {
    (attachment_headers(name, content_type), bytes).into_response()
}

#[derive(Debug, Deserialize, IntoParams)]
pub struct TrainedFileParams {
    /// Dynamic scenes, `scene.ply` and `scene.spz` only: the Gaussians moved by the deformation
    /// field to this normalised time (0..1 spans the training frames), in the canonical file's
    /// layout and Gaussian order (`labels.npy` still lines up). Default: the canonical Gaussians
    /// as stored.
    #[param(value_type = Option<TimeValue>)]
    pub time: Option<f64>,
}

#[utoipa::path(get, path = "/v1/scenes/{id}/trained/{file}", tag = "objects",
    params(("id" = String, Path, description = "scene id"),
           ("file" = String, Path, description = "scene.ply, scene.spz (compressed, encoded on \
             request), labels.npy, cameras.json, objects.json, metrics.json, skipped_pairs.json, \
             deformation.json or deformation.bin"),
           TrainedFileParams),
    responses((status = 200, description = "the file: JSON for the `.json` files, bytes for the others",
               content((BinaryFile = "application/octet-stream"), (Object = "application/json"))),
              (status = 400, description = "a time that is not a number or out of range, a time \
               with a file other than scene.ply or scene.spz, or a time for a static scene",
               body = ErrorBody),
              (status = 404, description = "unknown scene or file", body = ErrorBody),
              (status = 409, description = "the scene is not trained yet", body = ErrorBody),
              (status = 503, description = "with a time: no GPU to move the Gaussians on",
               body = ErrorBody)))]
pub async fn trained_file(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath((id, file)): UrlPath<(String, String)>,
    Query(params): Query<TrainedFileParams>,
) -> ApiResult<Response> {
    if let Some(time) = parse_time(params.time)? {
        return scene_at_time(&state, &caller, &id, &file, time).await;
    }
    stored_file(&state, &caller, &id, &file).await
}

/// `scene.ply` or `scene.spz` with the Gaussians where the deformation field puts them at `time`.
async fn scene_at_time(
    state: &AppState,
    caller: &Caller,
    id: &str,
    file: &str,
    time: f32,
) -> ApiResult<Response> {
    let format = match file {
        SCENE_FILE => SplatFormat::Ply,
        SPZ_FILE => SplatFormat::Spz,
        _ => {
            // An unknown scene or file is a 404 (and an untrained scene a 409) whatever the
            // query says; only a file that exists is refused for its time.
            state
                .core
                .serving
                .open_trained_file(id, caller, file)
                .await?;
            return Err(ApiError::bad_request(format!(
                "time: applies to {SCENE_FILE} and {SPZ_FILE} only, not {file}"
            )));
        }
    };
    let moved = state
        .core
        .serving
        .scene_at_time(id, caller, time, format)
        .await?;
    match moved {
        Some(bytes) => Ok(attachment(file, "application/octet-stream", bytes)),
        // Trained without a field: the stored Gaussians are the scene at every time.
        None => stored_file(state, caller, id, file).await,
    }
}

/// A file of the trained version as stored (`scene.spz` encoded from the stored PLY).
async fn stored_file(
    state: &AppState,
    caller: &Caller,
    id: &str,
    file: &str,
) -> ApiResult<Response> {
    if file == SPZ_FILE {
        let bytes = state.core.serving.scene_spz(id, caller).await?;
        return Ok(attachment(file, "application/octet-stream", bytes));
    }
    let opened = state
        .core
        .serving
        .open_trained_file(id, caller, file)
        .await?;
    // Streamed from the open file in chunks: a large PLY is never held whole in memory.
    let stream = tokio_util::io::ReaderStream::new(tokio::fs::File::from_std(opened.file));
    Ok((
        attachment_headers(file, content_type(file)),
        [(header::CONTENT_LENGTH, opened.len.to_string())],
        axum::body::Body::from_stream(stream),
    )
        .into_response())
}

#[utoipa::path(get, path = "/v1/scenes/{id}/objects/{level}/{object_id}/ply", tag = "objects",
    params(("id" = String, Path, description = "scene id"),
           ("level" = LevelName, Path, description = "small, middle or large"),
           ("object_id" = u32, Path, description = "object id at that level",
            maximum = 4294967295_u64)),
    responses((status = 200, description = "the object's Gaussians, Inria-layout PLY",
               content_type = "application/octet-stream", body = BinaryFile),
              (status = 400, description = "unknown level", body = ErrorBody),
              (status = 404, description = "unknown scene or object", body = ErrorBody),
              (status = 409, description = "the scene is not trained yet", body = ErrorBody)))]
pub async fn object_ply(
    state: State<AppState>,
    caller: Extension<Caller>,
    path: UrlPath<(String, String, u32)>,
) -> ApiResult<Response> {
    object_file(state, caller, path, SplatFormat::Ply).await
}

#[utoipa::path(get, path = "/v1/scenes/{id}/objects/{level}/{object_id}/spz", tag = "objects",
    params(("id" = String, Path, description = "scene id"),
           ("level" = LevelName, Path, description = "small, middle or large"),
           ("object_id" = u32, Path, description = "object id at that level",
            maximum = 4294967295_u64)),
    responses((status = 200, description = "the object's Gaussians, compressed SPZ (version 2)",
               content_type = "application/octet-stream", body = BinaryFile),
              (status = 400, description = "unknown level", body = ErrorBody),
              (status = 404, description = "unknown scene or object", body = ErrorBody),
              (status = 409, description = "the scene is not trained yet", body = ErrorBody)))]
pub async fn object_spz(
    state: State<AppState>,
    caller: Extension<Caller>,
    path: UrlPath<(String, String, u32)>,
) -> ApiResult<Response> {
    object_file(state, caller, path, SplatFormat::Spz).await
}

async fn object_file(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath((id, level, object_id)): UrlPath<(String, String, u32)>,
    format: SplatFormat,
) -> ApiResult<Response> {
    let level = parse_level(&level)?;
    let bytes = state
        .core
        .serving
        .object_export(&id, &caller, level, object_id, format)
        .await?;
    let name = format!("{}-{object_id}.{}", level.name(), format.extension());
    Ok(attachment(&name, "application/octet-stream", bytes))
}
