//! The cluster's workers as every API process sees them: from the `workers` rows each worker
//! slot keeps fresh, with a worker silent for longer than a lease counted as gone. Behind REST
//! `GET /v1/workers`, `/readyz`'s cluster summary and the `segsplat_cluster_workers` gauges.

use crate::core::ServiceCore;
use crate::store::workers::{WorkerRecord, WorkerState};
use crate::store::{Caller, StoreError, now_ms};

#[derive(Debug, thiserror::Error)]
pub enum WorkersFailure {
    /// Workers run every tenant's jobs; only an admin may see them.
    #[error("the cluster's workers are visible to admin tokens only")]
    NotAdmin,
    #[error(transparent)]
    Store(#[from] StoreError),
}

#[derive(Debug, Clone)]
pub struct WorkerStatus {
    pub record: WorkerRecord,
    /// Heartbeating within a lease and not stopped.
    pub alive: bool,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ClusterSummary {
    pub busy: usize,
    pub idle: usize,
    /// Registered, not stopped, but silent for longer than a lease (killed, or cut off).
    pub silent: usize,
}

/// Every registered worker, newest heartbeat first.
pub async fn list_workers(
    core: &ServiceCore,
    caller: &Caller,
) -> Result<Vec<WorkerStatus>, WorkersFailure> {
    if !caller.admin {
        return Err(WorkersFailure::NotAdmin);
    }
    cluster_workers(core).await
}

/// [`list_workers`] for the service itself (readiness, metrics).
pub async fn cluster_workers(core: &ServiceCore) -> Result<Vec<WorkerStatus>, WorkersFailure> {
    let silent_after_ms = (core.config.jobs.lease_secs * 1000.0).ceil() as i64;
    let now = now_ms();
    Ok(core
        .database
        .list_workers()
        .await?
        .into_iter()
        .map(|record| WorkerStatus {
            alive: record.state != WorkerState::Stopped
                && now - record.heartbeat_at_ms <= silent_after_ms,
            record,
        })
        .collect())
}

pub fn summarize(workers: &[WorkerStatus]) -> ClusterSummary {
    let mut summary = ClusterSummary::default();
    for worker in workers {
        match (worker.alive, worker.record.state) {
            (true, WorkerState::Busy) => summary.busy += 1,
            (true, _) => summary.idle += 1,
            (false, WorkerState::Stopped) => {}
            (false, _) => summary.silent += 1,
        }
    }
    summary
}
