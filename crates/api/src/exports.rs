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
use super::schema_names::{
    BinaryFile, LevelName, SkippedFramePair, TimeValue, TrainedBinaryFileName, TrainedCamera,
    TrainedObject,
};
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

/// A binary file of the trained version. The same route serves the JSON files too (their URLs
/// are the same), but the document gives each of those its own operation and schema, so that a
/// generated client parses JSON as JSON and hands bytes back as bytes: one operation answering
/// both, as before issue 41, made clients parse `scene.ply` as JSON (the first media type
/// listed) and gave the JSON arrays an object schema.
#[utoipa::path(get, path = "/v1/scenes/{id}/trained/{file}", tag = "objects",
    params(("id" = String, Path, description = "scene id"),
           ("file" = TrainedBinaryFileName, Path, description = "scene.ply, scene.spz \
             (compressed, encoded on request), labels.npy or deformation.bin (dynamic scenes); \
             the JSON files have their own operations"),
           TrainedFileParams),
    responses((status = 200, description = "the file's bytes",
               content_type = "application/octet-stream", body = BinaryFile),
              (status = 400, description = "a time that is not a number or out of range, a time \
               with a file other than scene.ply or scene.spz, or a time for a static scene",
               body = ErrorBody),
              (status = 404, description = "unknown scene, or a file this scene's trained \
               version does not have (deformation.bin for a static scene)", body = ErrorBody),
              (status = 409, description = "the scene is not trained yet", body = ErrorBody),
              (status = 503, description = "with a time: no GPU to move the Gaussians on",
               body = ErrorBody)))]
pub async fn trained_file(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath((id, file)): UrlPath<(String, String)>,
    Query(params): Query<TrainedFileParams>,
) -> ApiResult<Response> {
    trained(&state, &caller, &id, &file, params).await
}

async fn trained(
    state: &AppState,
    caller: &Caller,
    id: &str,
    file: &str,
    params: TrainedFileParams,
) -> ApiResult<Response> {
    if let Some(time) = parse_time(params.time)? {
        return scene_at_time(state, caller, id, file, time).await;
    }
    stored_file(state, caller, id, file).await
}

/// Declares the operation of one JSON file of the trained version: the same handler as
/// `trained_file` with the file's name fixed, documented with that file's schema. `time` is
/// not a parameter of theirs (it moves Gaussians); sent anyway, it is a 400 as it always was.
macro_rules! trained_json_file {
    ($(#[$doc:meta])* $name:ident, $path:literal, $file:literal, $body:tt, $what:literal,
     $missing:literal) => {
        $(#[$doc])*
        #[utoipa::path(get, path = $path, tag = "objects",
            params(("id" = String, Path, description = "scene id")),
            responses((status = 200, description = $what, body = $body),
                      (status = 400, description = "a `time` query parameter: it applies to \
                       scene.ply and scene.spz only", body = ErrorBody),
                      (status = 404, description = $missing, body = ErrorBody),
                      (status = 409, description = "the scene is not trained yet",
                       body = ErrorBody)))]
        pub async fn $name(
            State(state): State<AppState>,
            Extension(caller): Extension<Caller>,
            UrlPath(id): UrlPath<String>,
            Query(params): Query<TrainedFileParams>,
        ) -> ApiResult<Response> {
            trained(&state, &caller, &id, $file, params).await
        }
    };
}

trained_json_file!(
    /// `cameras.json`: the trained version's cameras in frame order (what a frame index means).
    trained_cameras,
    "/v1/scenes/{id}/trained/cameras.json",
    "cameras.json",
    [TrainedCamera],
    "the cameras, in frame order",
    "unknown scene"
);

trained_json_file!(
    /// `objects.json`: every object the segment_then_splat job found.
    trained_objects,
    "/v1/scenes/{id}/trained/objects.json",
    "objects.json",
    [TrainedObject],
    "the objects, by level then id",
    "unknown scene, or a scene trained by a reconstruct job (it finds no objects)"
);

trained_json_file!(
    /// `metrics.json`: the training report.
    trained_metrics,
    "/v1/scenes/{id}/trained/metrics.json",
    "metrics.json",
    Object,
    "the job's report: steps, Gaussians, timings, held-out quality and the settings it ran \
     with; its fields depend on the job kind",
    "unknown scene"
);

trained_json_file!(
    /// `skipped_pairs.json`: the (frame, object) pairs the object loss left out.
    trained_skipped_pairs,
    "/v1/scenes/{id}/trained/skipped_pairs.json",
    "skipped_pairs.json",
    [SkippedFramePair],
    "the frame and object pairs the object loss skipped (masks it could not trust)",
    "unknown scene, or a scene trained by a reconstruct job"
);

trained_json_file!(
    /// `deformation.json`: a dynamic scene's deformation field header.
    trained_deformation,
    "/v1/scenes/{id}/trained/deformation.json",
    "deformation.json",
    Object,
    "the deformation field's header: its shape, time range and where its weights lie in \
     deformation.bin",
    "unknown scene, or a static scene (it has no field)"
);

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
