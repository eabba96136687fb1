//! Downloads of a scene's trained version: the whole scene (`scene.ply`, or compressed
//! `scene.spz`), the labels sidecar (`labels.npy`, object ids per Gaussian in PLY order), cameras
//! and reports, and single objects as their own PLY or SPZ.

use axum::Extension;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};

use super::error::{ApiResult, ErrorBody};
use super::extract::UrlPath;
use super::params::parse_level;
use super::schema_names::{BinaryFile, LevelName};
use super::state::AppState;
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

#[utoipa::path(get, path = "/v1/scenes/{id}/trained/{file}", tag = "objects",
    params(("id" = String, Path, description = "scene id"),
           ("file" = String, Path, description = "scene.ply, scene.spz (compressed, encoded on \
             request), labels.npy, cameras.json, objects.json, metrics.json, skipped_pairs.json, \
             deformation.json or deformation.bin")),
    responses((status = 200, description = "the file: JSON for the `.json` files, bytes for the others",
               content((BinaryFile = "application/octet-stream"), (Object = "application/json"))),
              (status = 404, description = "unknown scene or file", body = ErrorBody),
              (status = 409, description = "the scene is not trained yet", body = ErrorBody)))]
pub async fn trained_file(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath((id, file)): UrlPath<(String, String)>,
) -> ApiResult<Response> {
    if file == SPZ_FILE {
        let bytes = state.core.serving.scene_spz(&id, &caller).await?;
        return Ok(attachment(&file, "application/octet-stream", bytes));
    }
    let opened = state
        .core
        .serving
        .open_trained_file(&id, &caller, &file)
        .await?;
    // Streamed from the open file in chunks: a large PLY is never held whole in memory.
    let stream = tokio_util::io::ReaderStream::new(tokio::fs::File::from_std(opened.file));
    Ok((
        attachment_headers(&file, content_type(&file)),
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
