//! `GET /v1/workers`: the cluster's worker slots, from every process that shares the database.

use axum::extract::State;
use axum::{Extension, Json};
use serde::Serialize;
use utoipa::ToSchema;

use super::error::{ApiError, ApiResult, ErrorBody};
use super::schema_names::WorkerStateName;
use super::state::AppState;
use segsplat_service::store::Caller;
use segsplat_service::usecases::workers::{self, WorkerStatus, WorkersFailure};

#[derive(Debug, Serialize, ToSchema)]
pub struct WorkerResponse {
    /// The slot's lease-owner name, `{instance}/{slot}`.
    pub id: String,
    pub instance: String,
    /// The GPU adapter's name, or `cpu`.
    pub device: String,
    pub kinds: Vec<String>,
    /// idle, busy or stopped, as last reported.
    #[schema(value_type = WorkerStateName)]
    pub state: String,
    /// The job it runs, when busy.
    pub job_id: Option<String>,
    /// Heartbeating within a lease and not stopped.
    pub alive: bool,
    pub started_at_ms: i64,
    pub heartbeat_at_ms: i64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct WorkerList {
    pub workers: Vec<WorkerResponse>,
    pub busy: usize,
    pub idle: usize,
    /// Registered, not stopped, silent for longer than a lease.
    pub silent: usize,
}

impl From<WorkerStatus> for WorkerResponse {
    fn from(status: WorkerStatus) -> Self {
        let record = status.record;
        Self {
            id: record.id,
            instance: record.instance,
            device: record.device,
            kinds: record.kinds,
            state: record.state.as_str().to_string(),
            job_id: record.job_id,
            alive: status.alive,
            started_at_ms: record.started_at_ms,
            heartbeat_at_ms: record.heartbeat_at_ms,
        }
    }
}

impl From<WorkersFailure> for ApiError {
    fn from(failure: WorkersFailure) -> Self {
        match failure {
            WorkersFailure::NotAdmin => ApiError::forbidden(failure.to_string()),
            WorkersFailure::Store(store) => store.into(),
        }
    }
}

/// Every worker slot registered by any process on this database (admin tokens only; with
/// authentication off, everyone), newest heartbeat first, with busy/idle/silent counts.
#[utoipa::path(get, path = "/v1/workers", tag = "ops",
    responses((status = 200, description = "every worker slot, newest heartbeat first",
               body = WorkerList),
              (status = 403, description = "the token is not an admin's", body = ErrorBody)))]
pub async fn list_workers(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
) -> ApiResult<Json<WorkerList>> {
    let statuses = workers::list_workers(&state.core, &caller).await?;
    let summary = workers::summarize(&statuses);
    Ok(Json(WorkerList {
        workers: statuses.into_iter().map(WorkerResponse::from).collect(),
        busy: summary.busy,
        idle: summary.idle,
        silent: summary.silent,
    }))
}
