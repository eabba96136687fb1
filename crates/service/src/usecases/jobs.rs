//! Jobs: queue one for a scene, look jobs up, list, cancel, and follow a job's events until it
//! ends. The one implementation behind REST `/v1/jobs` (events as Server-Sent Events) and gRPC
//! `GetJob`.

use std::time::Duration;

use futures::Stream;
use tokio::sync::broadcast::error::RecvError;
use tokio_util::sync::CancellationToken;

use super::job_bounds::{check_adapter_fit, check_job_bounds};
use crate::core::ServiceCore;
use crate::jobs::JobEventBus;
use crate::store::events::JobEventRecord;
use crate::store::jobs::{AttemptBounds, CancelOutcome, JobRecord, JobState};
use crate::store::{Caller, StoreError};

/// How often an event stream re-reads the database when no wake-up arrives (events written by
/// worker processes elsewhere).
const EVENT_POLL: Duration = Duration::from_millis(1000);
const EVENT_BATCH: i64 = 500;

#[derive(Debug, thiserror::Error)]
pub enum JobFailure {
    #[error("job {0} not found")]
    NotFound(String),
    #[error("scene {0} not found")]
    SceneNotFound(String),
    /// The request names the field at fault (`kind: ...`, `config: ...`, `state: ...`).
    #[error("{0}")]
    Invalid(String),
    /// A list filter names no job state.
    #[error("state: unknown job state {0:?}; use queued, running, succeeded, failed or cancelled")]
    UnknownState(String),
    #[error("job {job_id} already finished ({state})")]
    AlreadyFinished { job_id: String, state: &'static str },
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// What a cancel did.
#[derive(Debug, Clone, PartialEq)]
pub enum Cancelled {
    /// The job was queued and is now cancelled.
    Now(JobRecord),
    /// The job is running; its worker stops at its next step boundary.
    Requested(JobRecord),
}

/// Queues a job of `kind` for the scene, after checking the kind, its config, the service's
/// bounds and (for GPU kinds) that the first model fits this process's adapters.
pub async fn create_job(
    core: &ServiceCore,
    caller: &Caller,
    scene_id: &str,
    kind: &str,
    config: &serde_json::Value,
) -> Result<JobRecord, JobFailure> {
    let Some(handler) = core.handlers.get(kind) else {
        let kinds = core.handlers.kinds();
        let known = if kinds.is_empty() {
            "no job kinds are available in this build yet".to_string()
        } else {
            format!("known kinds: {}", kinds.join(", "))
        };
        return Err(JobFailure::Invalid(format!(
            "kind: unknown job kind {kind:?}; {known}"
        )));
    };
    let invalid = |message: String| JobFailure::Invalid(format!("config: {message}"));
    let config = handler.validate_config(config).map_err(invalid)?;
    check_job_bounds(&config, &core.config.jobs).map_err(invalid)?;
    if handler.needs_gpu()
        && let Some(scene) = core.database.get_scene(scene_id, caller).await?
    {
        check_adapter_fit(&config, scene.summary.sparse_point_count, &core.adapters)
            .map_err(invalid)?;
    }
    let job = core
        .database
        .insert_job(
            scene_id,
            kind,
            &config,
            AttemptBounds {
                max_attempts: core.config.jobs.max_attempts,
                max_lease_expiries: core.config.jobs.max_lease_expiries,
            },
            caller,
        )
        .await?
        .ok_or_else(|| JobFailure::SceneNotFound(scene_id.to_string()))?;
    core.bus.notify(&job.id);
    core.job_queued.notify_waiters();
    tracing::info!(job_id = %job.id, kind = %job.kind, %scene_id, "job queued");
    Ok(job)
}

/// The job, if the caller may see it.
pub async fn get_job(
    core: &ServiceCore,
    caller: &Caller,
    job_id: &str,
) -> Result<JobRecord, JobFailure> {
    core.database
        .get_job(job_id, caller)
        .await?
        .ok_or_else(|| JobFailure::NotFound(job_id.to_string()))
}

/// The caller's jobs, only those in `state` when it is given (`""` means all).
pub async fn list_jobs(
    core: &ServiceCore,
    caller: &Caller,
    state: Option<&str>,
) -> Result<Vec<JobRecord>, JobFailure> {
    let filter = match state {
        None | Some("") => None,
        Some(text) => {
            Some(JobState::parse(text).ok_or_else(|| JobFailure::UnknownState(text.to_string()))?)
        }
    };
    Ok(core.database.list_jobs(filter, caller).await?)
}

/// Cancels a queued job at once, or asks a running one to stop at its next step boundary.
pub async fn cancel_job(
    core: &ServiceCore,
    caller: &Caller,
    job_id: &str,
) -> Result<Cancelled, JobFailure> {
    let outcome = core.database.request_cancel(job_id, caller).await?;
    core.bus.notify(job_id);
    core.bus.notify_cancel(job_id);
    match outcome {
        CancelOutcome::Cancelled(job) => Ok(Cancelled::Now(job)),
        CancelOutcome::Requested(job) => Ok(Cancelled::Requested(job)),
        CancelOutcome::AlreadyFinished(job) => Err(JobFailure::AlreadyFinished {
            job_id: job_id.to_string(),
            state: job.state.as_str(),
        }),
        CancelOutcome::NotFound => Err(JobFailure::NotFound(job_id.to_string())),
    }
}

/// The job's events after `resume_after` (an event id; 0 for all): every stored one first,
/// then new ones as they happen. The stream ends after the job's final state, or when `stop`
/// is cancelled (the service is stopping).
pub async fn follow_job_events(
    core: &ServiceCore,
    caller: &Caller,
    job_id: &str,
    resume_after: i64,
    stop: CancellationToken,
) -> Result<impl Stream<Item = JobEventRecord> + use<>, JobFailure> {
    get_job(core, caller, job_id).await?;
    Ok(event_stream(
        core.clone(),
        caller.clone(),
        job_id.to_string(),
        resume_after,
        stop,
    ))
}

fn event_stream(
    core: ServiceCore,
    caller: Caller,
    job_id: String,
    mut last_id: i64,
    stop: CancellationToken,
) -> impl Stream<Item = JobEventRecord> {
    async_stream::stream! {
        let mut wakeups = core.bus.subscribe();
        loop {
            // Read the job before its events: a final state is written with its event in one
            // transaction, so once the job is final all its events are visible.
            let finished = match core.database.get_job(&job_id, &caller).await {
                Ok(Some(job)) => job.state.is_terminal(),
                Ok(None) => true,
                Err(error) => {
                    tracing::warn!(%error, "job events: cannot read job");
                    false
                }
            };
            let mut fetched_full_batch = false;
            match core.database.job_events_after(&job_id, last_id, EVENT_BATCH).await {
                Ok(events) => {
                    fetched_full_batch = events.len() as i64 == EVENT_BATCH;
                    for event in events {
                        last_id = event.id;
                        yield event;
                    }
                }
                Err(error) => tracing::warn!(%error, "job events: cannot read them"),
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
                        Ok(woken) if JobEventBus::concerns(&woken, &job_id) => return,
                        Ok(_) => {}
                        Err(RecvError::Lagged(_)) => return,
                        Err(RecvError::Closed) => std::future::pending::<()>().await,
                    }
                }
            };
            tokio::select! {
                _ = wait => {}
                _ = tokio::time::sleep(EVENT_POLL) => {}
                _ = stop.cancelled() => break,
            }
        }
    }
}
