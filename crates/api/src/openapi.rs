//! The OpenAPI 3.1 document: generated from the handlers' annotations, then completed with what
//! depends on the running configuration (which job kinds exist, whether tokens are required) and
//! with the answers every operation shares (`openapi_shared.rs`). The served document is thus
//! true of the server that serves it; `ApiDoc::openapi()` alone is the configuration-free part.

use axum::Json;
use axum::extract::State;
use serde_json::{Value, json};
use utoipa::OpenApi;

use super::openapi_shared::{add_shared_responses, declare_security};
use super::state::AppState;
use super::{error, exports, jobs, masks, objects, ops, query, scenes, schema_names, workers};

#[derive(OpenApi)]
#[openapi(
    info(title = "segsplat", description = "Open-vocabulary 3D segmentation service"),
    paths(
        scenes::upload_scene,
        scenes::list_scenes,
        scenes::get_scene,
        scenes::delete_scene,
        jobs::create_job,
        jobs::get_job,
        jobs::list_jobs,
        jobs::cancel_job,
        jobs::job_events,
        objects::list_objects,
        query::query_scene,
        masks::render_masks,
        masks::object_mask_png,
        exports::trained_file,
        exports::trained_cameras,
        exports::trained_objects,
        exports::trained_metrics,
        exports::trained_skipped_pairs,
        exports::trained_deformation,
        exports::object_ply,
        exports::object_spz,
        workers::list_workers,
        ops::healthz,
        ops::readyz,
        ops::metrics,
        openapi_json,
    ),
    components(schemas(
        error::ErrorBody,
        error::ErrorDetail,
        scenes::SceneResponse,
        scenes::SceneList,
        scenes::UndistortedLensResponse,
        scenes::CoefficientResponse,
        jobs::CreateJobRequest,
        jobs::JobResponse,
        jobs::JobList,
        jobs::JobEvent,
        workers::WorkerResponse,
        workers::WorkerList,
        objects::ObjectResponse,
        objects::ObjectList,
        query::QueryRequest,
        query::QueryMatchResponse,
        query::QueryResponse,
        masks::ViewRequest,
        segsplat_service::serving::PinholeIntrinsics,
        masks::MaskBody,
        masks::ObjectRef,
        masks::MasksRequest,
        masks::ObjectMasksResponse,
        masks::MasksResponse,
        ops::HealthResponse,
        ops::ReadinessResponse,
        ops::ClusterWorkers,
        // Referenced from parameters and annotations, which utoipa does not collect from.
        schema_names::BinaryFile,
        schema_names::TrainedBinaryFileName,
        schema_names::TrainedCamera,
        schema_names::TrainedObject,
        schema_names::SkippedFramePair,
        schema_names::GranularityName,
        schema_names::JobStateFilter,
        schema_names::JobStateName,
        schema_names::LevelName,
        schema_names::MaskFormatName,
        schema_names::TimeValue,
        schema_names::WorkerStateName,
    ))
)]
pub struct ApiDoc;

/// What the served document says that depends on the running configuration.
#[derive(Debug, Clone)]
pub struct DocumentFacts {
    /// Tokens are configured, so every route but the open ones needs one.
    pub auth: bool,
    /// The job kinds this server has handlers for.
    pub job_kinds: Vec<String>,
    /// `query.max_mask_side`: the largest image side a free camera may ask for.
    pub max_mask_side: u32,
}

impl DocumentFacts {
    pub fn of(state: &AppState) -> Self {
        Self {
            auth: state.core.config.auth.enabled(),
            job_kinds: state
                .core
                .handlers
                .kinds()
                .into_iter()
                .map(str::to_string)
                .collect(),
            max_mask_side: state.core.config.query.max_mask_side,
        }
    }
}

/// The document as served: the generated part, completed for `facts`.
pub fn document(facts: &DocumentFacts) -> Value {
    // Serialising the generated document cannot fail (it is plain data); an empty object would
    // only make the contract checks fail loudly.
    let mut document = serde_json::to_value(ApiDoc::openapi()).unwrap_or_default();
    describe_upload_body(&mut document);
    describe_event_stream(&mut document);
    state_view_limits(&mut document, facts.max_mask_side);
    add_shared_responses(&mut document, facts.auth);
    declare_security(&mut document, facts.auth);
    list_job_kinds(&mut document, &facts.job_kinds);
    document
}

/// `POST /v1/scenes` takes the archive's bytes as the raw body in any of the accepted media types,
/// or as the file field of a multipart form.
fn describe_upload_body(document: &mut Value) {
    let binary = json!({"schema": {"type": "string", "format": "binary"}});
    let mut content: serde_json::Map<String, Value> = scenes::RAW_ARCHIVE_TYPES
        .iter()
        .map(|media_type| (media_type.to_string(), binary.clone()))
        .collect();
    content.insert(
        "multipart/form-data".to_string(),
        json!({"schema": {
            "type": "object",
            "required": ["file"],
            "properties": {"file": {"type": "string", "format": "binary"}},
        }}),
    );
    if let Some(upload) = document.pointer_mut("/paths/~1v1~1scenes/post")
        && let Some(upload) = upload.as_object_mut()
    {
        upload.insert(
            "requestBody".to_string(),
            json!({
                "description": "a zip, tar or tar.gz dataset archive (the kind is read from \
                    the bytes), at most `limits.max_upload_bytes`",
                "required": true,
                "content": content,
            }),
        );
    }
}

/// `GET /v1/jobs/{id}/events` answers Server-Sent Events. OpenAPI 3.1 has no `itemSchema` (3.2
/// adds it for sequential media types), so the media type's `schema` describes each event, as
/// tools read it for `text/event-stream` (schemathesis validates every event of a stream against
/// it): the event's fields as the SSE format defines them, `data` holding a `JobEvent` as JSON.
fn describe_event_stream(document: &mut Value) {
    let event = json!({
        "title": "JobEventMessage",
        "description": "One Server-Sent Event: `id:` the event id (for `Last-Event-ID`), \
            `event:` its kind, `data:` a `JobEvent` as JSON.",
        "type": "object",
        "required": ["id", "event", "data"],
        "properties": {
            "id": {"type": "string", "pattern": "^[0-9]+$"},
            "event": {"type": "string", "minLength": 1},
            "data": {
                "type": "string",
                "contentMediaType": "application/json",
                "contentSchema": {"$ref": "#/components/schemas/JobEvent"},
            },
            "retry": {"type": "integer", "minimum": 0},
        },
        "additionalProperties": false,
    });
    let Some(operation) = document.pointer_mut("/paths/~1v1~1jobs~1{id}~1events/get") else {
        return;
    };
    if let Some(stream) = operation
        .pointer_mut("/responses/200/content/text~1event-stream")
        .and_then(Value::as_object_mut)
    {
        stream.insert("schema".to_string(), event);
    }
    // `Last-Event-ID` may be left out, but when sent it is a number: the `Option` it is read
    // into would otherwise make its schema nullable, and `null` is no event id (400).
    if let Some(parameters) = operation
        .get_mut("parameters")
        .and_then(Value::as_array_mut)
    {
        for parameter in parameters {
            if parameter["name"] == "Last-Event-ID" {
                parameter["schema"] = json!({"type": "integer", "format": "int64", "minimum": 0});
            }
        }
    }
}

/// A free camera's image may be at most `query.max_mask_side` pixels on a side (else 400), a
/// bound of this server's configuration.
fn state_view_limits(document: &mut Value, max_mask_side: u32) {
    for side in ["width", "height"] {
        let pointer = format!("/components/schemas/PinholeIntrinsics/properties/{side}");
        if let Some(side) = document
            .pointer_mut(&pointer)
            .and_then(Value::as_object_mut)
        {
            side.insert("maximum".to_string(), Value::from(max_mask_side));
        }
    }
}

/// `CreateJobRequest.kind` may only name a registered kind (else 422); which ones is known only
/// at run time.
fn list_job_kinds(document: &mut Value, kinds: &[String]) {
    if let Some(kind) = document.pointer_mut("/components/schemas/CreateJobRequest/properties/kind")
        && let Some(kind) = kind.as_object_mut()
    {
        kind.insert("enum".to_string(), Value::from(kinds.to_vec()));
    }
}

/// This document, for this server's configuration. Open, like the probes: it holds no tenant's
/// data and tells a client how to authenticate.
#[utoipa::path(get, path = "/v1/openapi.json", tag = "ops",
    responses((status = 200, description = "this document (OpenAPI 3.1)",
        content_type = "application/json", body = Object)))]
pub async fn openapi_json(State(state): State<AppState>) -> Json<Value> {
    Json(document(&DocumentFacts::of(&state)))
}
