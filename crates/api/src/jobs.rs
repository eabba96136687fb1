//! Job endpoints: queue, inspect, list, cancel, and follow progress as Server-Sent Events.

use std::convert::Infallible;

use axum::extract::State;
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::{Extension, Json};
use futures::{Stream, StreamExt};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::error::{ApiError, ApiResult, ErrorBody};
use super::extract::{JsonBody, Query, UrlPath};
use super::schema_names::{JobStateFilter, JobStateName};
use super::state::AppState;
use segsplat_service::store::Caller;
use segsplat_service::store::events::JobEventRecord;
use segsplat_service::store::jobs::JobRecord;
use segsplat_service::usecases::jobs::{self, Cancelled};

#[derive(Debug, Deserialize, ToSchema)]
pub struct CreateJobRequest {
    /// A job kind this server has registered (the served document lists them).
    pub kind: String,
    /// Kind-specific settings, validated by the kind's handler; absent: the kind's defaults.
    /// An object when given (`null` or any other JSON type is refused with 422).
    #[serde(default, deserialize_with = "config_object")]
    #[schema(value_type = Object)]
    pub config: Option<serde_json::Map<String, serde_json::Value>>,
}

/// `config`, when present, must be an object: `null` is not "the defaults" (leave the field out
/// for those), and the schema says `type: object`.
fn config_object<'de, D>(
    deserializer: D,
) -> Result<Option<serde_json::Map<String, serde_json::Value>>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    serde_json::Map::deserialize(deserializer).map(Some)
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JobResponse {
    pub id: String,
    pub scene_id: String,
    pub kind: String,
    /// queued, running, succeeded, failed or cancelled.
    #[schema(value_type = JobStateName)]
    pub state: String,
    /// What the job was created with: the fields it gave and the kind's defaults for the rest
    /// (for `segment_then_splat`, `scene_sized` names the fields the scene decides instead).
    #[schema(value_type = Object)]
    pub config: serde_json::Value,
    /// The settings the job runs with, once its worker has resolved them from the scene
    /// (steps, objects per level, background, mask source, Gaussian budget); absent until then.
    #[schema(value_type = Option<Object>)]
    pub settings: Option<serde_json::Value>,
    pub attempts: u32,
    pub max_attempts: u32,
    /// Lease expiries after the job had saved a newer checkpoint (the worker's process died
    /// while the job progressed); not counted in `attempts`.
    pub lease_expiries: u32,
    pub max_lease_expiries: u32,
    pub cancel_requested: bool,
    pub error: Option<String>,
    /// Latest progress: stage, step, total_steps, metrics, eta_secs.
    #[schema(value_type = Option<Object>)]
    pub progress: Option<serde_json::Value>,
    pub lease_owner: Option<String>,
    pub created_at_ms: i64,
    pub updated_at_ms: i64,
    pub started_at_ms: Option<i64>,
    pub finished_at_ms: Option<i64>,
    /// The tenant that owns it (its scene's).
    pub tenant: String,
}

impl From<JobRecord> for JobResponse {
    fn from(job: JobRecord) -> Self {
        Self {
            id: job.id,
            scene_id: job.scene_id,
            kind: job.kind,
            state: job.state.as_str().to_string(),
            config: job.config,
            settings: job.settings,
            attempts: job.attempts,
            max_attempts: job.max_attempts,
            lease_expiries: job.lease_expiries,
            max_lease_expiries: job.max_lease_expiries,
            cancel_requested: job.cancel_requested,
            error: job.error,
            progress: job.progress,
            lease_owner: job.lease_owner,
            created_at_ms: job.created_at_ms,
            updated_at_ms: job.updated_at_ms,
            started_at_ms: job.started_at_ms,
            finished_at_ms: job.finished_at_ms,
            tenant: job.tenant,
        }
    }
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JobList {
    pub jobs: Vec<JobResponse>,
}

#[derive(Debug, Deserialize, IntoParams)]
pub struct JobListParams {
    /// Only jobs in this state.
    #[param(value_type = Option<JobStateFilter>)]
    pub state: Option<String>,
}

/// Queues a job of `kind` for the scene.
#[utoipa::path(post, path = "/v1/scenes/{id}/jobs", tag = "jobs",
    params(("id" = String, Path, description = "scene id")),
    request_body = CreateJobRequest,
    responses((status = 201, description = "the job, queued; `Location` names it",
            body = JobResponse,
            headers(("Location" = String, description = "the job's URL"))),
        (status = 404, description = "no such scene (for this caller)", body = ErrorBody),
        (status = 422, description = "unknown kind or invalid config", body = ErrorBody)))]
pub async fn create_job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(scene_id): UrlPath<String>,
    JsonBody(request): JsonBody<CreateJobRequest>,
) -> ApiResult<(StatusCode, HeaderMap, Json<JobResponse>)> {
    let config = request
        .config
        .map_or(serde_json::Value::Null, serde_json::Value::Object);
    let job = jobs::create_job(&state.core, &caller, &scene_id, &request.kind, &config).await?;
    let mut headers = HeaderMap::new();
    if let Ok(location) = format!("/v1/jobs/{}", job.id).parse() {
        headers.insert(header::LOCATION, location);
    }
    Ok((StatusCode::CREATED, headers, Json(job.into())))
}

#[utoipa::path(get, path = "/v1/jobs/{id}", tag = "jobs",
    params(("id" = String, Path, description = "job id")),
    responses((status = 200, description = "the job", body = JobResponse),
        (status = 404, description = "no such job (for this caller)", body = ErrorBody)))]
pub async fn get_job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
) -> ApiResult<Json<JobResponse>> {
    let job = jobs::get_job(&state.core, &caller, &id).await?;
    Ok(Json(job.into()))
}

#[utoipa::path(get, path = "/v1/jobs", tag = "jobs", params(JobListParams),
    responses((status = 200, description = "the jobs the caller may see", body = JobList),
        (status = 400, description = "unknown state", body = ErrorBody)))]
pub async fn list_jobs(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Query(params): Query<JobListParams>,
) -> ApiResult<Json<JobList>> {
    let jobs = jobs::list_jobs(&state.core, &caller, params.state.as_deref()).await?;
    Ok(Json(JobList {
        jobs: jobs.into_iter().map(JobResponse::from).collect(),
    }))
}

/// Cancels a queued job at once (200) or asks a running one to stop at its next step boundary
/// (202).
#[utoipa::path(post, path = "/v1/jobs/{id}/cancel", tag = "jobs",
    params(("id" = String, Path, description = "job id")),
    responses((status = 200, description = "cancelled", body = JobResponse),
        (status = 202, description = "cancel requested", body = JobResponse),
        (status = 404, description = "no such job (for this caller)", body = ErrorBody),
        (status = 409, description = "already finished", body = ErrorBody)))]
pub async fn cancel_job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
) -> ApiResult<(StatusCode, Json<JobResponse>)> {
    match jobs::cancel_job(&state.core, &caller, &id).await? {
        Cancelled::Now(job) => Ok((StatusCode::OK, Json(job.into()))),
        Cancelled::Requested(job) => Ok((StatusCode::ACCEPTED, Json(job.into()))),
    }
}

/// The job's events as Server-Sent Events: every stored event first, then new ones as they
/// happen; the stream ends after the job's final state. Event names are the event kinds
/// (`state`, `progress`, `cancel_requested`); ids allow resuming with `Last-Event-ID`.
#[utoipa::path(get, path = "/v1/jobs/{id}/events", tag = "jobs",
    params(("id" = String, Path, description = "job id"),
        ("Last-Event-ID" = Option<i64>, Header, minimum = 0,
            description = "resume after this event id (the `id:` of the last event received); \
                anything but a whole number from 0 is refused with 400")),
    responses((status = 200, description = "Server-Sent Events, one per job event: `id:` the \
            event id, `event:` its kind, `data:` a JSON `JobEvent`",
            content_type = "text/event-stream", body = String),
        (status = 400, description = "`Last-Event-ID` is not a whole number from 0",
            body = ErrorBody),
        (status = 404, description = "no such job (for this caller)", body = ErrorBody)))]
pub async fn job_events(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
    headers: HeaderMap,
) -> ApiResult<Sse<impl Stream<Item = Result<Event, Infallible>>>> {
    let resume_after = match headers.get("last-event-id") {
        None => 0,
        Some(value) => parse_last_event_id(value.as_bytes())?,
    };
    let events = jobs::follow_job_events(
        &state.core,
        &caller,
        &id,
        resume_after,
        state.shutdown.clone(),
    )
    .await?;
    Ok(Sse::new(events.map(sse_event)).keep_alive(KeepAlive::default()))
}

/// `Last-Event-ID`: an event id, a whole number from 0 (an id this server sent, or 0 for all).
/// Anything else, the empty value included, is refused rather than read as "from the start".
fn parse_last_event_id(value: &[u8]) -> Result<i64, ApiError> {
    std::str::from_utf8(value)
        .ok()
        .filter(|text| !text.is_empty() && text.bytes().all(|byte| byte.is_ascii_digit()))
        .and_then(|text| text.parse::<i64>().ok())
        .ok_or_else(|| {
            ApiError::bad_request(
                "Last-Event-ID: give the id of the last event received (a whole number from 0)",
            )
        })
}

/// One job event: the `data:` of each Server-Sent Event of `GET /v1/jobs/{id}/events`.
#[derive(Debug, Serialize, ToSchema)]
pub struct JobEvent {
    /// Increasing across all jobs; also the event's `id:`, for `Last-Event-ID`.
    pub id: i64,
    pub job_id: String,
    pub at_ms: i64,
    /// `state`, `progress`, `cancel_requested` or a job kind's own; also the event's `event:`.
    pub kind: String,
    /// `state`: the new state (and error); `progress`: stage, step, total_steps, metrics,
    /// eta_secs.
    #[schema(value_type = Object)]
    pub payload: serde_json::Value,
}

fn sse_event(event: JobEventRecord) -> Result<Event, Infallible> {
    let sse = Event::default()
        .id(event.id.to_string())
        .event(event.kind.clone());
    let data = JobEvent {
        id: event.id,
        job_id: event.job_id,
        at_ms: event.at_ms,
        kind: event.kind,
        payload: event.payload,
    };
    // A JSON value always serialises; the fallback only keeps the stream's type infallible.
    Ok(sse.data(serde_json::to_string(&data).unwrap_or_default()))
}
