//! Scene endpoints: streamed upload, list, get, delete.

use std::path::Path;

use axum::Extension;
use axum::Json;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use futures::StreamExt;
use serde::{Deserialize, Serialize};
use tokio::io::AsyncWriteExt;
use utoipa::{IntoParams, ToSchema};

use super::error::{ApiError, ApiResult, ErrorBody};
use super::extract::{Query, UrlPath};
use super::schema_names::LevelName;
use super::state::AppState;
use segsplat_service::store::Caller;
use segsplat_service::store::process_tag::process_tag;
use segsplat_service::store::scenes::SceneRecord;
use segsplat_service::usecases::scenes;

/// Raw upload bodies we accept; the archive kind itself is sniffed from the bytes.
pub const RAW_ARCHIVE_TYPES: [&str; 7] = [
    "application/zip",
    "application/x-zip-compressed",
    "application/x-tar",
    "application/gzip",
    "application/x-gzip",
    "application/x-compressed-tar",
    "application/octet-stream",
];

#[derive(Debug, Serialize, ToSchema)]
pub struct SceneResponse {
    pub id: String,
    pub name: String,
    /// `colmap`, `nerfstudio`, `blender` (also D-NeRF), `nerfies` (also HyperNeRF) or `neu3d`.
    pub format: String,
    pub frame_count: u32,
    /// Whether frames carry capture times (D-NeRF, Nerfies/HyperNeRF, Neu3D).
    pub dynamic: bool,
    /// Distinct capture times (normalised to 0..1); 0 for static scenes.
    pub time_count: u32,
    /// Distinct image sizes as `[width, height]`.
    pub resolutions: Vec<[u32; 2]>,
    pub sparse_point_count: u64,
    /// Levels (`small`, `middle`, `large`) with user-provided masks.
    #[schema(value_type = Vec<LevelName>)]
    pub mask_levels: Vec<String>,
    /// Files in the upload the dataset does not use (not cameras, frames, masks or the
    /// format's own files); they were not stored.
    pub ignored_file_count: u64,
    /// The first 20 of them, relative to the dataset.
    pub ignored_files: Vec<String>,
    pub created_at_ms: i64,
    /// The tenant that owns it (the uploading token's).
    pub tenant: String,
    /// Camera models with lens distortion: their frames (and masks) are undistorted to pinhole
    /// cameras with the same `fx, fy, cx, cy` and size before any job sees them. Empty when
    /// every camera is pinhole.
    pub undistorted: Vec<UndistortedLensResponse>,
}

/// A distorted camera model of the upload and what its frames become.
#[derive(Debug, Serialize, ToSchema)]
pub struct UndistortedLensResponse {
    /// The model as the dataset names it (COLMAP's `OPENCV`, `SIMPLE_RADIAL`, ...).
    pub model: String,
    /// Its distortion coefficients by COLMAP's names (`k1`, `k2`, `p1`, `p2`, ...), in order.
    pub coefficients: Vec<CoefficientResponse>,
    /// Frames with this camera.
    pub frame_count: u32,
    /// Their images' size, `[width, height]`.
    pub size: [u32; 2],
    /// The undistorted images' size, `[width, height]`.
    pub undistorted_size: [u32; 2],
}

/// One distortion coefficient.
#[derive(Debug, Serialize, ToSchema)]
pub struct CoefficientResponse {
    pub name: String,
    pub value: f64,
}

impl From<&SceneRecord> for SceneResponse {
    fn from(record: &SceneRecord) -> Self {
        let summary = &record.summary;
        Self {
            id: record.id.clone(),
            name: record.name.clone(),
            format: serde_json::to_value(summary.format)
                .ok()
                .and_then(|value| value.as_str().map(str::to_string))
                .unwrap_or_default(),
            frame_count: summary.frame_count,
            dynamic: summary.time_count > 0,
            time_count: summary.time_count,
            resolutions: summary.resolutions.clone(),
            sparse_point_count: summary.sparse_point_count,
            mask_levels: summary
                .mask_levels
                .iter()
                .map(|level| level.name().to_string())
                .collect(),
            ignored_file_count: summary.ignored_file_count,
            ignored_files: summary.ignored_files.clone(),
            created_at_ms: record.created_at_ms,
            tenant: record.tenant.clone(),
            undistorted: summary
                .undistorted
                .iter()
                .map(|lens| UndistortedLensResponse {
                    model: lens.model.clone(),
                    coefficients: lens
                        .coefficients
                        .iter()
                        .map(|c| CoefficientResponse {
                            name: c.name.clone(),
                            value: c.value,
                        })
                        .collect(),
                    frame_count: lens.frame_count,
                    size: lens.size,
                    undistorted_size: lens.undistorted_size,
                })
                .collect(),
        }
    }
}

#[derive(Debug, Serialize, ToSchema)]
pub struct SceneList {
    pub scenes: Vec<SceneResponse>,
}

#[derive(Debug, Deserialize, IntoParams)]
pub struct UploadParams {
    /// Display name; defaults to the uploaded file's name or the scene id.
    pub name: Option<String>,
}

/// Uploads a dataset archive (zip, tar or tar.gz; COLMAP, nerfstudio, Blender/D-NeRF,
/// Nerfies/HyperNeRF or Neu3D layout), as the
/// raw body or as the one file field of a multipart form. The body is streamed to disk.
// The request body (raw bytes in several media types, or a multipart file) is declared by
// `openapi::describe_upload_body`: utoipa would describe `Vec<u8>` as an array of integers.
#[utoipa::path(post, path = "/v1/scenes", tag = "scenes", params(UploadParams),
    responses(
        (status = 201, description = "the scene, stored; `Location` names it",
            body = SceneResponse,
            headers(("Location" = String, description = "the scene's URL"))),
        (status = 400, description = "malformed archive or unsafe entry", body = ErrorBody),
        (status = 413, description = "over an upload or unpack limit", body = ErrorBody),
        (status = 415, description = "not an archive or not a known dataset format", body = ErrorBody),
        (status = 422, description = "inconsistent dataset (missing or undecodable image, ...)", body = ErrorBody),
    ))]
pub async fn upload_scene(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Query(params): Query<UploadParams>,
    request: Request,
) -> ApiResult<(StatusCode, HeaderMap, Json<SceneResponse>)> {
    let config = &state.core.config;
    let scratch_dir = config.scratch_dir();
    tokio::fs::create_dir_all(&scratch_dir)
        .await
        .map_err(|error| {
            // The path is the server's business: logged, not returned.
            tracing::error!(%error, path = %scratch_dir.display(), "cannot create the upload folder");
            ApiError::internal("the server cannot create its upload folder")
        })?;
    let temp = tempfile::Builder::new()
        // Named after this process, so a restart's sweep knows when its writer is gone.
        .prefix(&format!("upload-{}-", process_tag()))
        .tempfile_in(&scratch_dir)
        .map_err(|error| ApiError::internal(format!("cannot create an upload file: {error}")))?;
    let uploaded_name = receive_upload(&state, request, temp.as_file()).await?;
    let name = params
        .name
        .filter(|name| !name.trim().is_empty())
        .or(uploaded_name);
    let record = scenes::create_scene(&state.core, temp, name, caller.tenant).await?;
    let mut headers = HeaderMap::new();
    if let Ok(location) = format!("/v1/scenes/{}", record.id).parse() {
        headers.insert(header::LOCATION, location);
    }
    Ok((
        StatusCode::CREATED,
        headers,
        Json(SceneResponse::from(&record)),
    ))
}

/// Streams the archive into `file`, enforcing the size limit; returns the uploaded file's name
/// (without extension) when the client sent one.
async fn receive_upload(
    state: &AppState,
    request: Request,
    file: &std::fs::File,
) -> ApiResult<Option<String>> {
    let max_bytes = state.core.config.limits.max_upload_bytes;
    let too_large = || {
        ApiError::payload_too_large(format!(
            "upload exceeds limits.max_upload_bytes ({max_bytes} bytes)"
        ))
    };
    let declared_length = request
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|value| value.to_str().ok())
        .and_then(|value| value.parse::<u64>().ok());
    if declared_length.is_some_and(|length| length > max_bytes) {
        return Err(too_large());
    }
    let content_type = request
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|value| value.to_str().ok())
        .unwrap_or("")
        .to_string();
    let essence = content_type
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    let cloned = file
        .try_clone()
        .map_err(|error| ApiError::internal(format!("cannot open the upload file: {error}")))?;
    let mut writer = UploadWriter {
        file: tokio::fs::File::from_std(cloned),
        written: 0,
        max_bytes,
    };
    let mut uploaded_name = None;
    if essence == "multipart/form-data" {
        let mut multipart = Multipart::from_request(request, state)
            .await
            .map_err(|error| ApiError::bad_request(format!("bad multipart body: {error}")))?;
        let mut found = false;
        while let Some(mut field) = multipart.next_field().await.map_err(multipart_error)? {
            if field.file_name().is_none() && field.name() != Some("file") {
                continue;
            }
            uploaded_name = field.file_name().and_then(file_stem);
            while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
                writer
                    .write(&chunk)
                    .await
                    .map_err(|error| error.unwrap_or_else(too_large))?;
            }
            found = true;
            break;
        }
        if !found {
            return Err(ApiError::bad_request(
                "multipart upload has no file field (send the archive as a field named \"file\")",
            ));
        }
    } else if RAW_ARCHIVE_TYPES.contains(&essence.as_str()) {
        let mut body = request.into_body().into_data_stream();
        while let Some(chunk) = body.next().await {
            let chunk = chunk
                .map_err(|error| ApiError::bad_request(format!("upload interrupted: {error}")))?;
            writer
                .write(&chunk)
                .await
                .map_err(|error| error.unwrap_or_else(too_large))?;
        }
    } else {
        return Err(ApiError::unsupported_media_type(format!(
            "Content-Type {content_type:?} is not accepted; send multipart/form-data or one of {}",
            RAW_ARCHIVE_TYPES.join(", ")
        )));
    }
    writer
        .file
        .flush()
        .await
        .map_err(|error| ApiError::internal(format!("cannot write the upload: {error}")))?;
    Ok(uploaded_name)
}

fn multipart_error(error: axum::extract::multipart::MultipartError) -> ApiError {
    ApiError::bad_request(format!("bad multipart body: {error}"))
}

fn file_stem(file_name: &str) -> Option<String> {
    let base = Path::new(file_name)
        .file_name()?
        .to_string_lossy()
        .into_owned();
    let stem = base
        .trim_end_matches(".tar.gz")
        .trim_end_matches(".tgz")
        .trim_end_matches(".zip")
        .trim_end_matches(".tar")
        .to_string();
    (!stem.is_empty()).then_some(stem)
}

struct UploadWriter {
    file: tokio::fs::File,
    written: u64,
    max_bytes: u64,
}

impl UploadWriter {
    /// `Err(None)` when the limit is passed, `Err(Some(..))` on a write failure.
    async fn write(&mut self, chunk: &[u8]) -> Result<(), Option<ApiError>> {
        self.written += chunk.len() as u64;
        if self.written > self.max_bytes {
            return Err(None);
        }
        self.file.write_all(chunk).await.map_err(|error| {
            Some(ApiError::internal(format!(
                "cannot write the upload: {error}"
            )))
        })
    }
}

/// The caller's tenant's scenes (every tenant's for an admin), oldest first.
#[utoipa::path(get, path = "/v1/scenes", tag = "scenes",
    responses((status = 200, description = "the scenes the caller may see", body = SceneList)))]
pub async fn list_scenes(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
) -> ApiResult<Json<SceneList>> {
    let records = scenes::list_scenes(&state.core, &caller).await?;
    Ok(Json(SceneList {
        scenes: records.iter().map(SceneResponse::from).collect(),
    }))
}

#[utoipa::path(get, path = "/v1/scenes/{id}", tag = "scenes",
    params(("id" = String, Path, description = "scene id")),
    responses((status = 200, description = "the scene", body = SceneResponse),
        (status = 404, description = "no such scene (for this caller)", body = ErrorBody)))]
pub async fn get_scene(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
) -> ApiResult<Json<SceneResponse>> {
    let record = scenes::get_scene(&state.core, &caller, &id).await?;
    Ok(Json(SceneResponse::from(&record)))
}

/// Deletes a scene, its jobs, objects and files; refused while one of its jobs is queued or
/// running.
#[utoipa::path(delete, path = "/v1/scenes/{id}", tag = "scenes",
    params(("id" = String, Path, description = "scene id")),
    responses((status = 204, description = "deleted; no body"),
        (status = 404, description = "no such scene (for this caller)", body = ErrorBody),
        (status = 409, description = "one of its jobs is queued or running", body = ErrorBody)))]
pub async fn delete_scene(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
) -> ApiResult<StatusCode> {
    scenes::delete_scene(&state.core, &caller, &id).await?;
    Ok(StatusCode::NO_CONTENT)
}
