//! Text queries against a scene's objects: `POST /v1/scenes/{id}/query`, and the core that the
//! gRPC `Query` method shares (look-ups, text encoding through the shared cached encoder,
//! scoring by [`crate::language::answer_query`]).

use std::sync::Arc;
use std::time::Instant;

use axum::extract::{Path as UrlPath, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::error::{ApiError, ApiResult, ErrorBody};
use super::masks::{MaskBody, ViewRequest, parse_mask_format, parse_time};
use super::state::AppState;
use crate::language::{
    CANONICAL_PHRASES, CandidateObject, DEFAULT_RELEVANCY_THRESHOLD, EmbeddingWidthMismatch,
    QueryOptions, QueryOptionsError, SharedTextEncoder, TextEncoderUnavailable, answer_query,
};
use crate::pipeline::segment_then_splat::objects::ObjectSummary;
use crate::store::Caller;
use crate::store::objects::ObjectRecord;
use crate::store::{Database, StoreError};

/// Why a query got no answer; each maps to one REST status and one gRPC code.
#[derive(Debug, thiserror::Error)]
pub enum QueryFailure {
    #[error(transparent)]
    BadOptions(#[from] QueryOptionsError),
    #[error("text: must not be empty")]
    EmptyText,
    #[error("scene {0} not found")]
    SceneNotFound(String),
    #[error("scene {0} has no trained objects yet; run a segment_then_splat job")]
    NoObjects(String),
    #[error(
        "scene {scene_id} has no object embeddings for model {model_id}; run a \
         segment_then_splat job with that CLIP image model configured"
    )]
    NoEmbeddings { scene_id: String, model_id: String },
    #[error(transparent)]
    NoTextEncoder(#[from] TextEncoderUnavailable),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("encoding the text failed: {0}")]
    Encoding(String),
    #[error("text queries are unavailable: {0}")]
    EmbeddingWidth(#[from] EmbeddingWidthMismatch),
}

/// One matching object with its geometry.
#[derive(Debug, Clone)]
pub struct QueryMatch {
    pub object: ObjectRecord,
    pub score: f32,
    pub relevancy: f32,
}

#[derive(Debug, Clone)]
pub struct QueryOutcome {
    pub matched: bool,
    pub matches: Vec<QueryMatch>,
    /// The embedding model the scores come from.
    pub model_id: String,
}

/// Answers `text` on `scene_id`: checks in the order a caller can act on (bad request, unknown
/// scene, no encoder, nothing trained), then scores.
pub async fn run_query(
    database: &Database,
    text_encoder: &Arc<SharedTextEncoder>,
    scene_id: &str,
    caller: &Caller,
    text: &str,
    options: QueryOptions,
) -> Result<QueryOutcome, QueryFailure> {
    let started = Instant::now();
    options.validate()?;
    if text.trim().is_empty() {
        return Err(QueryFailure::EmptyText);
    }
    if database.get_scene(scene_id, caller).await?.is_none() {
        return Err(QueryFailure::SceneNotFound(scene_id.to_string()));
    }
    let model_id = text_encoder
        .image_model_id()
        .ok_or(TextEncoderUnavailable::NotConfigured)?;
    let objects = database.list_objects(scene_id, None).await?;
    if objects.is_empty() {
        return Err(QueryFailure::NoObjects(scene_id.to_string()));
    }
    let embeddings = database.list_embeddings(scene_id, &model_id).await?;
    if embeddings.is_empty() {
        return Err(QueryFailure::NoEmbeddings {
            scene_id: scene_id.to_string(),
            model_id,
        });
    }
    let encoder = Arc::clone(text_encoder);
    let query_text = text.to_string();
    let texts = tokio::task::spawn_blocking(move || {
        let encoder = encoder.encoder()?;
        let mut texts = vec![query_text.as_str()];
        texts.extend(CANONICAL_PHRASES);
        encoder
            .encode(&texts)
            .map_err(|error| QueryFailure::Encoding(error.to_string()))
    })
    .await
    .map_err(|error| QueryFailure::Encoding(format!("worker thread failed: {error}")))??;
    let Some((query, canonical)) = texts.split_first() else {
        return Err(QueryFailure::Encoding("no text embedding".to_string()));
    };
    let canonical: Vec<&[f32]> = canonical.iter().map(|vector| &vector[..]).collect();
    let candidates: Vec<CandidateObject> = embeddings
        .iter()
        .map(|embedding| CandidateObject {
            level: embedding.level,
            object_id: embedding.object_id,
            vector: &embedding.vector,
        })
        .collect();
    let answer = answer_query(query, &canonical, &candidates, &options)?;
    let matches = answer
        .objects
        .iter()
        .filter_map(|scored| {
            let object = objects.iter().find(|object| {
                object.level == scored.level && object.object_id == scored.object_id
            })?;
            Some(QueryMatch {
                object: object.clone(),
                score: scored.score,
                relevancy: scored.relevancy,
            })
        })
        .collect();
    metrics::histogram!("segsplat_query_seconds").record(started.elapsed().as_secs_f64());
    Ok(QueryOutcome {
        matched: answer.matched,
        matches,
        model_id,
    })
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
            QueryFailure::Store(_) | QueryFailure::Encoding(_) => ApiError::internal(message),
        }
    }
}

/// A text query. Omitted fields take their defaults.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct QueryRequest {
    pub text: String,
    /// `auto` (default: the better of the best middle and best large object), `small`,
    /// `middle` or `large`.
    pub granularity: Option<String>,
    /// How many matching objects to return, 1..=100 (default 1).
    pub top_k: Option<usize>,
    /// Minimum LERF relevancy against "object", "things", "stuff", "texture" for a match
    /// (default 0.55; 0.5 = no better than those phrases).
    pub threshold: Option<f32>,
    /// When given, each match carries its mask rendered for this view.
    pub view: Option<ViewRequest>,
    /// `coco_rle` (default) or `png`.
    pub mask_format: Option<String>,
    /// With `view`: also the visible-only masks (the part no other Gaussian hides).
    pub visible_masks: Option<bool>,
    /// Dynamic scenes: the normalised capture time of the answer (0..1 spans the training
    /// frames). Centroids, bounds and masks are where the objects are then. Default: the view's
    /// `time`, else its frame's time, else the scene's first time. Static scenes ignore it.
    pub time: Option<f32>,
}

/// One matching object.
#[derive(Debug, Serialize, ToSchema)]
pub struct QueryMatchResponse {
    /// `small`, `middle` or `large`.
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
            threshold: self.threshold.unwrap_or(DEFAULT_RELEVANCY_THRESHOLD),
        })
    }
}

#[utoipa::path(post, path = "/v1/scenes/{id}/query", tag = "objects",
    params(("id" = String, Path, description = "scene id")),
    request_body = QueryRequest,
    responses((status = 200, body = QueryResponse),
              (status = 400, description = "bad granularity, top_k, threshold, view, mask \
               format or empty text",
               body = ErrorBody),
              (status = 404, description = "unknown scene", body = ErrorBody),
              (status = 409, description = "no trained objects or embeddings yet",
               body = ErrorBody),
              (status = 503, description = "no text encoder configured", body = ErrorBody)))]
pub async fn query_scene(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
    Json(request): Json<QueryRequest>,
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
    let outcome = run_query(
        &state.database,
        &state.text_encoder,
        &id,
        &caller,
        &request.text,
        options,
    )
    .await?;
    let moved = if outcome.matches.is_empty() {
        None
    } else {
        state
            .serving
            .objects_at(&id, &caller, time, view.as_ref())
            .await?
    };
    let masks = match view {
        Some(view) if !outcome.matches.is_empty() => {
            let objects = outcome
                .matches
                .iter()
                .map(|found| (found.object.level, found.object.object_id))
                .collect();
            let visible = request.visible_masks.unwrap_or(false);
            state
                .serving
                .render_masks(&id, &caller, view, time, objects, visible, format)
                .await?
        }
        _ => Vec::new(),
    };
    Ok(Json(QueryResponse {
        matched: outcome.matched,
        objects: outcome
            .matches
            .iter()
            .enumerate()
            .map(|(rank, found)| {
                let place = placement(&found.object, moved.as_deref());
                QueryMatchResponse {
                    level: found.object.level.name().to_string(),
                    object_id: found.object.object_id,
                    score: found.score,
                    relevancy: found.relevancy,
                    centroid: place.centroid,
                    bounds_min: place.bounds_min,
                    bounds_max: place.bounds_max,
                    mask: masks.get(rank).map(|masks| MaskBody::from(&masks.mask)),
                    visible_mask: masks
                        .get(rank)
                        .and_then(|masks| masks.visible_mask.as_ref())
                        .map(MaskBody::from),
                }
            })
            .collect(),
        model_id: outcome.model_id,
    }))
}

/// Where an object is: its stored summary, or where a dynamic scene has it at the asked time.
pub struct Placement {
    pub centroid: [f32; 3],
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
}

pub fn placement(object: &ObjectRecord, moved: Option<&[ObjectSummary]>) -> Placement {
    let at_time = moved.and_then(|summaries| {
        summaries
            .iter()
            .find(|s| s.level == object.level && s.object_id == object.object_id)
    });
    match at_time {
        Some(summary) => Placement {
            centroid: summary.centroid,
            bounds_min: summary.bounds_min,
            bounds_max: summary.bounds_max,
        },
        None => Placement {
            centroid: object.centroid,
            bounds_min: object.bounds_min,
            bounds_max: object.bounds_max,
        },
    }
}
