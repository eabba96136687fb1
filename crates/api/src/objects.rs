//! Object endpoints: what a finished `segment_then_splat` job found in a scene.

use axum::extract::State;
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::error::{ApiError, ApiResult, ErrorBody};
use super::extract::{Query, UrlPath};
use super::params::{parse_level, parse_time};
use super::schema_names::{LevelName, TimeValue};
use super::state::AppState;
use segsplat_service::store::Caller;
use segsplat_service::store::objects::ObjectRecord;
use segsplat_service::usecases;
use segsplat_service::usecases::objects::ListObjectsError;

/// One object at one granularity level.
#[derive(Debug, Serialize, ToSchema)]
pub struct ObjectResponse {
    /// `small`, `middle` or `large`.
    #[schema(value_type = LevelName)]
    pub level: String,
    pub object_id: u32,
    pub gaussian_count: u64,
    /// Opacity-weighted centre of its Gaussians, world units.
    pub centroid: [f32; 3],
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
    /// 0..1 RGB.
    pub mean_color: [f32; 3],
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ObjectList {
    pub objects: Vec<ObjectResponse>,
}

#[derive(Debug, Deserialize, IntoParams)]
pub struct ObjectListParams {
    /// Only objects of this level (`small`, `middle`, `large`).
    #[param(value_type = Option<LevelName>)]
    pub level: Option<String>,
    /// Dynamic scenes: centroids and bounds where the objects are at this normalised time
    /// (0..1 spans the training frames). Default: the scene's first time, as stored.
    #[param(value_type = Option<TimeValue>)]
    pub time: Option<f64>,
}

impl From<&ObjectRecord> for ObjectResponse {
    fn from(record: &ObjectRecord) -> Self {
        Self {
            level: record.level.name().to_string(),
            object_id: record.object_id,
            gaussian_count: record.gaussian_count,
            centroid: record.centroid,
            bounds_min: record.bounds_min,
            bounds_max: record.bounds_max,
            mean_color: record.mean_color,
        }
    }
}

#[utoipa::path(get, path = "/v1/scenes/{id}/objects", tag = "objects",
    params(("id" = String, Path, description = "scene id"), ObjectListParams),
    responses((status = 200, description = "the scene's objects (none before a \
               segment_then_splat job succeeded)", body = ObjectList),
              (status = 400, description = "unknown level or a time that is not a number",
               body = ErrorBody),
              (status = 404, description = "no such scene (for this caller)", body = ErrorBody),
              (status = 409, description = "with a time: the trained version that moves the \
               objects is missing", body = ErrorBody)))]
pub async fn list_objects(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
    Query(params): Query<ObjectListParams>,
) -> ApiResult<Json<ObjectList>> {
    let level = params.level.as_deref().map(parse_level).transpose()?;
    let time = parse_time(params.time)?;
    let records = usecases::objects::list_objects(
        &state.core.database,
        &state.core.serving,
        &caller,
        &id,
        level,
        time,
    )
    .await?;
    Ok(Json(ObjectList {
        objects: records.iter().map(ObjectResponse::from).collect(),
    }))
}

impl From<ListObjectsError> for ApiError {
    fn from(error: ListObjectsError) -> Self {
        match error {
            ListObjectsError::SceneNotFound(_) => ApiError::not_found(error.to_string()),
            ListObjectsError::Store(store) => store.into(),
            ListObjectsError::Serve(failure) => failure.into(),
        }
    }
}
