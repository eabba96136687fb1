//! Text queries against a scene's objects, with masks for a view when asked: the one
//! implementation behind REST `POST /v1/scenes/{id}/query`, gRPC `Query` / `StreamQuery` and the
//! CLI's `query` and `eval` (look-ups in the order a caller can act on, text encoding through
//! the shared cached encoder, scoring by [`segsplat_vision::language::answer_query`], placement
//! at the asked time for dynamic scenes, masks rendered by the serving cache).

use std::sync::Arc;

use segsplat_method::segment_then_splat::objects::ObjectSummary;
use segsplat_vision::language::{
    CANONICAL_PHRASES, CandidateObject, EmbeddingWidthMismatch, QueryOptions, QueryOptionsError,
    SharedTextEncoder, TextEncoderUnavailable, answer_query,
};

use super::serving::{EncodedObjectMasks, ServeFailure, Serving};
use crate::serving::{EncodedMask, MaskFormat, MaskView};
use crate::store::objects::ObjectRecord;
use crate::store::{Caller, Database, StoreError};

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
    super::observe::timed("segsplat_query_seconds", async move {
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
        Ok(QueryOutcome {
            matched: answer.matched,
            matches,
            model_id,
        })
    })
    .await
}

/// A query, and what to render with its answer.
#[derive(Debug, Clone)]
pub struct QueryRequest {
    pub scene_id: String,
    pub text: String,
    pub options: QueryOptions,
    /// Dynamic scenes: the normalised time of the answer (centroids, bounds and masks are where
    /// the objects are then); `None` is the view's time, else the scene's first.
    pub time: Option<f32>,
    /// Render each match's mask for this view.
    pub masks: Option<MaskRequest>,
}

/// Masks to render for every match of a query.
#[derive(Debug, Clone)]
pub struct MaskRequest {
    pub view: MaskView,
    pub format: MaskFormat,
    /// Also the visible-only masks (the part no other Gaussian hides).
    pub visible: bool,
}

/// One matching object, placed at the asked time, with its masks when a view was asked for.
#[derive(Debug, Clone)]
pub struct AnsweredObject {
    /// The stored object with its centroid and bounds where it is at the asked time.
    pub object: ObjectRecord,
    pub score: f32,
    pub relevancy: f32,
    pub mask: Option<EncodedMask>,
    pub visible_mask: Option<EncodedMask>,
}

#[derive(Debug, Clone)]
pub struct QueryAnswer {
    /// False when no object reaches the threshold (then `objects` is empty).
    pub matched: bool,
    /// Best first.
    pub objects: Vec<AnsweredObject>,
    /// The embedding model the scores come from.
    pub model_id: String,
}

/// Why a query with masks got no answer: the query itself, or placing and rendering its matches.
#[derive(Debug, thiserror::Error)]
pub enum QueryError {
    #[error(transparent)]
    Query(#[from] QueryFailure),
    #[error(transparent)]
    Serve(#[from] ServeFailure),
}

/// Answers a query and places (and, with a view, renders) every match.
pub async fn query_with_masks(
    database: &Database,
    text_encoder: &Arc<SharedTextEncoder>,
    serving: &Serving,
    caller: &Caller,
    request: QueryRequest,
) -> Result<QueryAnswer, QueryError> {
    let outcome = run_query(
        database,
        text_encoder,
        &request.scene_id,
        caller,
        &request.text,
        request.options,
    )
    .await?;
    if outcome.matches.is_empty() {
        // Nothing to render, but a bad view is still a bad request (400 / INVALID_ARGUMENT),
        // not "no match": the answer must not depend on whether the text found something.
        if let Some(masks) = &request.masks {
            serving
                .check_view(&request.scene_id, caller, &masks.view)
                .await?;
        }
        return Ok(QueryAnswer {
            matched: outcome.matched,
            objects: Vec::new(),
            model_id: outcome.model_id,
        });
    }
    let view = request.masks.as_ref().map(|masks| &masks.view);
    let moved = serving
        .objects_at(&request.scene_id, caller, request.time, view)
        .await?;
    let masks: Vec<EncodedObjectMasks> = match request.masks {
        Some(asked) => {
            let objects = outcome
                .matches
                .iter()
                .map(|found| (found.object.level, found.object.object_id))
                .collect();
            serving
                .render_masks(
                    &request.scene_id,
                    caller,
                    asked.view,
                    request.time,
                    objects,
                    asked.visible,
                    asked.format,
                )
                .await?
        }
        None => Vec::new(),
    };
    // `render_masks` answers in the order it was asked, one per match.
    let mut masks = masks.into_iter();
    let objects = outcome
        .matches
        .into_iter()
        .map(|found| {
            let rendered = masks.next();
            AnsweredObject {
                object: placed(found.object, moved.as_deref()),
                score: found.score,
                relevancy: found.relevancy,
                visible_mask: rendered
                    .as_ref()
                    .and_then(|masks| masks.visible_mask.clone()),
                mask: rendered.map(|masks| masks.mask),
            }
        })
        .collect();
    Ok(QueryAnswer {
        matched: outcome.matched,
        objects,
        model_id: outcome.model_id,
    })
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

/// The object with its centroid and bounds where a dynamic scene has it at the asked time.
pub fn placed(mut object: ObjectRecord, moved: Option<&[ObjectSummary]>) -> ObjectRecord {
    let place = placement(&object, moved);
    object.centroid = place.centroid;
    object.bounds_min = place.bounds_min;
    object.bounds_max = place.bounds_max;
    object
}
