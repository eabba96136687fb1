//! `POST /v1/scenes/{id}/query`: parses the request, calls the query use case
//! ([`segsplat_service::usecases::query::query_with_masks`]) and maps its answer and errors.

use axum::extract::State;
use axum::http::StatusCode;
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::error::{ApiError, ApiResult, ErrorBody};
use super::extract::{JsonBody, UrlPath};
use super::masks::{MaskBody, ViewRequest};
use super::params::{parse_mask_format, parse_time};
use super::schema_names::{GranularityName, LevelName, MaskFormatName, TimeValue};
use super::state::AppState;
use segsplat_service::store::Caller;
use segsplat_service::usecases::query::{
    MaskRequest, QueryError, QueryFailure, QueryRequest as CoreQuery, query_with_masks,
};
use segsplat_vision::language::{DEFAULT_RELEVANCY_THRESHOLD, QueryOptions, QueryOptionsError};

impl From<QueryError> for ApiError {
    fn from(error: QueryError) -> Self {
        match error {
            QueryError::Query(failure) => failure.into(),
            QueryError::Serve(failure) => failure.into(),
        }
    }
}

impl From<QueryFailure> for ApiError {
    fn from(failure: QueryFailure) -> Self {
        let message = failure.to_string();
        match failure {
            QueryFailure::BadOptions(_) | QueryFailure::EmptyText => ApiError::bad_request(message),
            QueryFailure::SceneNotFound(_) => ApiError::not_found(message),
            QueryFailure::NoObjects(_) | QueryFailure::NoEmbeddings { .. } => {
                ApiError::conflict(message)
            }
            QueryFailure::NoTextEncoder(_) | QueryFailure::EmbeddingWidth(_) => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message)
            }
            QueryFailure::Store(store) => store.into(),
            QueryFailure::Encoding(_) => ApiError::internal(message),
        }
    }
}

/// A text query. Omitted fields take their defaults.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct QueryRequest {
    /// What to look for; not empty or only spaces.
    #[schema(min_length = 1, pattern = r"\S")]
    pub text: String,
    /// `auto` (default: the better of the best middle and best large object), `small`,
    /// `middle` or `large`.
    #[schema(value_type = Option<GranularityName>)]
    pub granularity: Option<String>,
    /// How many matching objects to return, 1..=100 (default 1).
    #[schema(minimum = 1, maximum = 100)]
    pub top_k: Option<usize>,
    /// Minimum LERF relevancy against "object", "things", "stuff", "texture" for a match
    /// (default 0.55; 0.5 = no better than those phrases).
    #[schema(minimum = 0.0, maximum = 1.0)]
    pub threshold: Option<f64>,
    /// When given, each match carries its mask rendered for this view.
    pub view: Option<ViewRequest>,
    /// `coco_rle` (default) or `png`.
    #[schema(value_type = Option<MaskFormatName>)]
    pub mask_format: Option<String>,
    /// With `view`: also the visible-only masks (the part no other Gaussian hides).
    pub visible_masks: Option<bool>,
    /// Dynamic scenes: the normalised capture time of the answer (0..1 spans the training
    /// frames). Centroids, bounds and masks are where the objects are then. Default: the view's
    /// `time`, else its frame's time, else the scene's first time. Static scenes ignore it.
    #[schema(value_type = Option<TimeValue>)]
    pub time: Option<f64>,
}

/// One matching object.
#[derive(Debug, Serialize, ToSchema)]
pub struct QueryMatchResponse {
    /// `small`, `middle` or `large`.
    #[schema(value_type = LevelName)]
    pub level: String,
    pub object_id: u32,
    /// Cosine similarity of the text and object embeddings.
    pub score: f32,
    /// Calibrated against the canonical phrases, 0..1.
    pub relevancy: f32,
    pub centroid: [f32; 3],
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
    /// With a `view`: alpha > 0.5 of the object rendered alone, occluded parts included.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mask: Option<MaskBody>,
    /// With a `view` and `visible_masks`: the part of the mask no other Gaussian hides.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub visible_mask: Option<MaskBody>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct QueryResponse {
    /// False when no object reaches the threshold (then `objects` is empty).
    pub matched: bool,
    /// Best first.
    pub objects: Vec<QueryMatchResponse>,
    /// The embedding model the scores come from.
    pub model_id: String,
}

impl QueryRequest {
    fn options(&self) -> Result<QueryOptions, QueryFailure> {
        let defaults = QueryOptions::default();
        Ok(QueryOptions {
            granularity: match &self.granularity {
                Some(name) => name.parse()?,
                None => defaults.granularity,
            },
            top_k: self.top_k.unwrap_or(defaults.top_k),
            // Checked before narrowing: a value just past 1 (or below 0) would round onto the
            // bound as `f32` and pass the options' own check, against the documented range.
            threshold: match self.threshold {
                Some(value) if (0.0..=1.0).contains(&value) => value as f32,
                Some(value) => return Err(QueryOptionsError::Threshold(value as f32).into()),
                None => DEFAULT_RELEVANCY_THRESHOLD,
            },
        })
    }
}

#[utoipa::path(post, path = "/v1/scenes/{id}/query", tag = "objects",
    params(("id" = String, Path, description = "scene id")),
    request_body = QueryRequest,
    responses((status = 200, description = "the matching objects, best first",
               body = QueryResponse),
              (status = 400, description = "bad granularity, top_k, threshold, view, mask \
               format or empty text",
               body = ErrorBody),
              (status = 404, description = "unknown scene", body = ErrorBody),
              (status = 409, description = "no trained objects or embeddings yet",
               body = ErrorBody),
              (status = 503, description = "no text encoder configured (or, with a view, no \
               GPU to render on)", body = ErrorBody),
              (status = 504, description = "rendering the masks took too long",
               body = ErrorBody)))]
pub async fn query_scene(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
    JsonBody(request): JsonBody<QueryRequest>,
) -> ApiResult<Json<QueryResponse>> {
    let options = request.options()?;
    // Bad view or format fail before the (slower) text encoding.
    let view = request
        .view
        .as_ref()
        .map(ViewRequest::to_view)
        .transpose()?;
    let format = parse_mask_format(request.mask_format.as_deref())?;
    let time = match parse_time(request.time)? {
        Some(time) => Some(time),
        None => request
            .view
            .as_ref()
            .map(ViewRequest::time)
            .transpose()?
            .flatten(),
    };
    let masks = view.map(|view| MaskRequest {
        view,
        format,
        visible: request.visible_masks.unwrap_or(false),
    });
    let answer = query_with_masks(
        &state.core.database,
        &state.core.text_encoder,
        &state.core.serving,
        &caller,
        CoreQuery {
            scene_id: id,
            text: request.text,
            options,
            time,
            masks,
        },
    )
    .await?;
    Ok(Json(QueryResponse {
        matched: answer.matched,
        objects: answer
            .objects
            .iter()
            .map(|found| QueryMatchResponse {
                level: found.object.level.name().to_string(),
                object_id: found.object.object_id,
                score: found.score,
                relevancy: found.relevancy,
                centroid: found.object.centroid,
                bounds_min: found.object.bounds_min,
                bounds_max: found.object.bounds_max,
                mask: found.mask.as_ref().map(MaskBody::from),
                visible_mask: found.visible_mask.as_ref().map(MaskBody::from),
            })
            .collect(),
        model_id: answer.model_id,
    }))
}
