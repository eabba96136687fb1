//! Object endpoints: what a finished `segment_then_splat` job found in a scene.

use axum::extract::{Path as UrlPath, Query, State};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::error::{ApiError, ApiResult, ErrorBody};
use super::masks::parse_time;
use super::query::placement;
use super::state::AppState;
use crate::scene::Level;
use crate::store::Caller;
use crate::store::objects::ObjectRecord;

/// One object at one granularity level.
#[derive(Debug, Serialize, ToSchema)]
pub struct ObjectResponse {
    /// `small`, `middle` or `large`.
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
    pub level: Option<String>,
    /// Dynamic scenes: centroids and bounds where the objects are at this normalised time
    /// (0..1 spans the training frames). Default: the scene's first time, as stored.
    pub time: Option<f32>,
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

pub fn parse_level(name: &str) -> Result<Level, ApiError> {
    Level::ALL
        .into_iter()
        .find(|level| level.name() == name)
        .ok_or_else(|| {
            ApiError::bad_request(format!(
                "level: unknown value {name:?}; expected small, middle or large"
            ))
        })
}

#[utoipa::path(get, path = "/v1/scenes/{id}/objects", tag = "objects",
    params(("id" = String, Path, description = "scene id"), ObjectListParams),
    responses((status = 200, body = ObjectList), (status = 400, body = ErrorBody),
              (status = 404, body = ErrorBody)))]
pub async fn list_objects(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
    Query(params): Query<ObjectListParams>,
) -> ApiResult<Json<ObjectList>> {
    let level = params.level.as_deref().map(parse_level).transpose()?;
    state
        .database
        .get_scene(&id, &caller)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("scene {id} not found")))?;
    let time = parse_time(params.time)?;
    let records = state.database.list_objects(&id, level).await?;
    let moved = match time {
        Some(time) if !records.is_empty() => {
            state
                .serving
                .objects_at(&id, &caller, Some(time), None)
                .await?
        }
        _ => None,
    };
    Ok(Json(ObjectList {
        objects: records
            .iter()
            .map(|record| {
                let place = placement(record, moved.as_deref());
                ObjectResponse {
                    centroid: place.centroid,
                    bounds_min: place.bounds_min,
                    bounds_max: place.bounds_max,
                    ..ObjectResponse::from(record)
                }
            })
            .collect(),
    }))
}
