//! Job endpoints: queue, inspect, list, cancel, and follow progress as Server-Sent Events.

use std::convert::Infallible;
use std::time::Duration;

use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::{Extension, Json};
use futures::Stream;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::error::{ApiError, ApiResult, ErrorBody};
use super::state::AppState;
use segsplat_service::store::Caller;
use segsplat_service::store::jobs::{AttemptBounds, CancelOutcome, JobRecord, JobState};
use segsplat_service::usecases::job_bounds::{check_adapter_fit, check_job_bounds};

/// How often an SSE stream re-reads the database when no wake-up arrives (events written by
/// worker processes elsewhere).
const SSE_POLL: Duration = Duration::from_millis(1000);
const SSE_BATCH: i64 = 500;

#[derive(Debug, Deserialize, ToSchema)]
pub struct CreateJobRequest {
    /// A registered job kind.
    pub kind: String,
    /// Kind-specific settings, validated by the kind's handler.
    #[serde(default)]
    #[schema(value_type = Object)]
    pub config: serde_json::Value,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JobResponse {
    pub id: String,
    pub scene_id: String,
    pub kind: String,
    /// queued, running, succeeded, failed or cancelled.
    pub state: String,
    #[schema(value_type = Object)]
    pub config: serde_json::Value,
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
    pub state: Option<String>,
}

/// Queues a job of `kind` for the scene.
#[utoipa::path(post, path = "/v1/scenes/{id}/jobs", tag = "jobs",
    params(("id" = String, Path, description = "scene id")),
    request_body = CreateJobRequest,
    responses((status = 201, body = JobResponse), (status = 404, body = ErrorBody),
        (status = 422, description = "unknown kind or invalid config", body = ErrorBody)))]
pub async fn create_job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(scene_id): UrlPath<String>,
    Json(request): Json<CreateJobRequest>,
) -> ApiResult<(StatusCode, HeaderMap, Json<JobResponse>)> {
    let Some(handler) = state.handlers.get(&request.kind) else {
        let kinds = state.handlers.kinds();
        let known = if kinds.is_empty() {
            "no job kinds are available in this build yet".to_string()
        } else {
            format!("known kinds: {}", kinds.join(", "))
        };
        return Err(ApiError::unprocessable(format!(
            "kind: unknown job kind {:?}; {known}",
            request.kind
        )));
    };
    let config = handler
        .validate_config(&request.config)
        .map_err(|message| ApiError::unprocessable(format!("config: {message}")))?;
    check_job_bounds(&config, &state.config.jobs)
        .map_err(|message| ApiError::unprocessable(format!("config: {message}")))?;
    if handler.needs_gpu()
        && let Some(scene) = state.database.get_scene(&scene_id, &caller).await?
    {
        check_adapter_fit(
            &config,
            scene.summary.sparse_point_count,
            &state.workers.adapters,
        )
        .map_err(|message| ApiError::unprocessable(format!("config: {message}")))?;
    }
    let job = state
        .database
        .insert_job(
            &scene_id,
            &request.kind,
            &config,
            AttemptBounds {
                max_attempts: state.config.jobs.max_attempts,
                max_lease_expiries: state.config.jobs.max_lease_expiries,
            },
            &caller,
        )
        .await?
        .ok_or_else(|| ApiError::not_found(format!("scene {scene_id} not found")))?;
    state.bus.notify(&job.id);
    state.job_queued.notify_waiters();
    tracing::info!(job_id = %job.id, kind = %job.kind, %scene_id, "job queued");
    let mut headers = HeaderMap::new();
    if let Ok(location) = format!("/v1/jobs/{}", job.id).parse() {
        headers.insert(header::LOCATION, location);
    }
    Ok((StatusCode::CREATED, headers, Json(job.into())))
}

#[utoipa::path(get, path = "/v1/jobs/{id}", tag = "jobs",
    params(("id" = String, Path, description = "job id")),
    responses((status = 200, body = JobResponse), (status = 404, body = ErrorBody)))]
pub async fn get_job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
) -> ApiResult<Json<JobResponse>> {
    let job = state
        .database
        .get_job(&id, &caller)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("job {id} not found")))?;
    Ok(Json(job.into()))
}

#[utoipa::path(get, path = "/v1/jobs", tag = "jobs", params(JobListParams),
    responses((status = 200, body = JobList), (status = 400, body = ErrorBody)))]
pub async fn list_jobs(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Query(params): Query<JobListParams>,
) -> ApiResult<Json<JobList>> {
    let filter = match params.state.as_deref() {
        None | Some("") => None,
        Some(text) => Some(JobState::parse(text).ok_or_else(|| {
            ApiError::bad_request(format!(
                "state: unknown job state {text:?}; use queued, running, succeeded, failed or \
                 cancelled"
            ))
        })?),
    };
    let jobs = state.database.list_jobs(filter, &caller).await?;
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
        (status = 404, body = ErrorBody), (status = 409, description = "already finished", body = ErrorBody)))]
pub async fn cancel_job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
) -> ApiResult<(StatusCode, Json<JobResponse>)> {
    let outcome = state.database.request_cancel(&id, &caller).await?;
    state.bus.notify(&id);
    match outcome {
        CancelOutcome::Cancelled(job) => Ok((StatusCode::OK, Json(job.into()))),
        CancelOutcome::Requested(job) => Ok((StatusCode::ACCEPTED, Json(job.into()))),
        CancelOutcome::AlreadyFinished(job) => Err(ApiError::conflict(format!(
            "job {id} already finished ({})",
            job.state.as_str()
        ))),
        CancelOutcome::NotFound => Err(ApiError::not_found(format!("job {id} not found"))),
    }
}

/// The job's events as Server-Sent Events: every stored event first, then new ones as they
/// happen; the stream ends after the job's final state. Event names are the event kinds
/// (`state`, `progress`, `cancel_requested`); ids allow resuming with `Last-Event-ID`.
#[utoipa::path(get, path = "/v1/jobs/{id}/events", tag = "jobs",
    params(("id" = String, Path, description = "job id")),
    responses((status = 200, description = "text/event-stream of job events"),
        (status = 404, body = ErrorBody)))]
pub async fn job_events(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
    headers: HeaderMap,
) -> ApiResult<Sse<impl Stream<Item = Result<Event, Infallible>>>> {
    if state.database.get_job(&id, &caller).await?.is_none() {
        return Err(ApiError::not_found(format!("job {id} not found")));
    }
    let resume_after = headers
        .get("last-event-id")
        .and_then(|value| value.to_str().ok())
        .and_then(|value| value.parse::<i64>().ok())
        .unwrap_or(0);
    Ok(Sse::new(event_stream(state, caller, id, resume_after)).keep_alive(KeepAlive::default()))
}

fn event_stream(
    state: AppState,
    caller: Caller,
    job_id: String,
    mut last_id: i64,
) -> impl Stream<Item = Result<Event, Infallible>> {
    async_stream::stream! {
        let mut wakeups = state.bus.subscribe();
        loop {
            // Read the job before its events: a final state is written with its event in one
            // transaction, so once the job is final all its events are visible.
            let finished = match state.database.get_job(&job_id, &caller).await {
                Ok(Some(job)) => job.state.is_terminal(),
                Ok(None) => true,
                Err(error) => {
                    tracing::warn!(%error, "SSE: cannot read job");
                    false
                }
            };
            let mut fetched_full_batch = false;
            match state.database.job_events_after(&job_id, last_id, SSE_BATCH).await {
                Ok(events) => {
                    fetched_full_batch = events.len() as i64 == SSE_BATCH;
                    for event in events {
                        last_id = event.id;
                        let data = serde_json::json!({
                            "id": event.id,
                            "job_id": event.job_id,
                            "at_ms": event.at_ms,
                            "kind": event.kind,
                            "payload": event.payload,
                        });
                        yield Ok(Event::default()
                            .id(event.id.to_string())
                            .event(event.kind)
                            .data(data.to_string()));
                    }
                }
                Err(error) => tracing::warn!(%error, "SSE: cannot read job events"),
            }
            if fetched_full_batch {
                continue;
            }
            if finished {
                break;
            }
            let wait = async {
                loop {
                    match wakeups.recv().await {
                        Ok(woken) if woken == job_id => return,
                        Ok(_) => {}
                        Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => return,
                        Err(tokio::sync::broadcast::error::RecvError::Closed) => {
                            std::future::pending::<()>().await
                        }
                    }
                }
            };
            tokio::select! {
                _ = wait => {}
                _ = tokio::time::sleep(SSE_POLL) => {}
                _ = state.shutdown.cancelled() => break,
            }
        }
    }
}
