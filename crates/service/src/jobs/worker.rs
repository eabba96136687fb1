//! One worker slot: lease a job, run its handler with a heartbeat alongside, record the outcome.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;
use tracing::{Instrument, info, info_span, warn};

use super::handler_run::HandlerRun;
use super::outage::run_through_outages;
use super::scene_cache::SceneFileCache;
use super::{HandlerRegistry, JobEventBus, JobFailure};
use crate::config::JobsConfig;
use crate::store::jobs::{AttemptOutcome, HeartbeatOutcome, JobRecord, JobState};
use crate::store::workers::WorkerState;
use crate::store::{BlobStore, Database, StoreError};

/// How long a finished attempt keeps trying to record its outcome while the database is down.
const OUTCOME_RETRY: Duration = Duration::from_secs(120);
use segsplat_gpu::GpuContext;
use segsplat_vision::models::ModelsStatus;

/// What every worker shares.
#[derive(Clone)]
pub(crate) struct WorkerShared {
    pub database: Database,
    pub blobs: Arc<dyn BlobStore>,
    pub models: Arc<ModelsStatus>,
    pub handlers: HandlerRegistry,
    pub bus: JobEventBus,
    pub jobs: JobsConfig,
    /// Woken when a job is queued in this process.
    pub job_queued: Arc<Notify>,
    pub shutdown: CancellationToken,
    /// Per-attempt scratch folders live here.
    pub scratch_dir: PathBuf,
    /// Local copies of scenes whose files are in an object store.
    pub scene_cache: Arc<SceneFileCache>,
    /// How long a stopping worker waits for its handler before handing the job back anyway.
    pub shutdown_grace: Duration,
}

pub(crate) struct Worker {
    pub shared: WorkerShared,
    /// Lease owner name, unique per process and slot.
    pub name: String,
    pub gpu: Option<Arc<GpuContext>>,
}

impl Worker {
    pub async fn run(self) {
        let kinds = self.shared.handlers.kinds_for(self.gpu.is_some());
        let poll = Duration::from_millis(self.shared.jobs.poll_interval_ms);
        let lease_ms = (self.shared.jobs.lease_secs * 1000.0).ceil() as i64;
        info!(worker = %self.name, ?kinds, "worker started");
        metrics::gauge!("segsplat_workers_idle").increment(1.0);
        let device = self
            .gpu
            .as_ref()
            .map_or("cpu".to_string(), |gpu| gpu.report.name.clone());
        let instance = self
            .name
            .rsplit_once('/')
            .map_or(&*self.name, |(instance, _)| instance);
        if let Err(error) = self
            .shared
            .database
            .register_worker(&self.name, instance, &device, &kinds)
            .await
        {
            warn!(worker = %self.name, %error, "registering the worker failed; it runs anyway");
        }
        // Idle heartbeats are written once per `heartbeat_secs`, not on every poll or wake-up:
        // readers call a worker silent only after a whole lease.
        let heartbeat_every = Duration::from_secs_f64(self.shared.jobs.heartbeat_secs);
        let mut idle_recorded: Option<Instant> = None;
        while !self.shared.shutdown.is_cancelled() {
            if idle_recorded.is_none_or(|at| at.elapsed() >= heartbeat_every) {
                self.record_state(WorkerState::Idle, None).await;
                idle_recorded = Some(Instant::now());
            }
            let claimed = self
                .shared
                .database
                .claim_job(&self.name, &kinds, lease_ms)
                .await;
            match claimed {
                Ok(Some(job)) => {
                    self.shared.bus.notify(&job.id);
                    self.record_state(WorkerState::Busy, Some(&job.id)).await;
                    idle_recorded = None;
                    metrics::gauge!("segsplat_workers_idle").decrement(1.0);
                    metrics::gauge!("segsplat_workers_busy").increment(1.0);
                    let span = info_span!("job", job_id = %job.id, kind = %job.kind,
                        attempt = job.attempts, worker = %self.name);
                    self.run_job(job).instrument(span).await;
                    metrics::gauge!("segsplat_workers_busy").decrement(1.0);
                    metrics::gauge!("segsplat_workers_idle").increment(1.0);
                }
                Ok(None) => {
                    tokio::select! {
                        _ = self.shared.job_queued.notified() => {}
                        _ = tokio::time::sleep(poll) => {}
                        _ = self.shared.shutdown.cancelled() => {}
                    }
                }
                Err(error) => {
                    warn!(worker = %self.name, %error, "claiming a job failed; retrying");
                    tokio::select! {
                        _ = tokio::time::sleep(poll) => {}
                        _ = self.shared.shutdown.cancelled() => {}
                    }
                }
            }
        }
        metrics::gauge!("segsplat_workers_idle").decrement(1.0);
        self.record_state(WorkerState::Stopped, None).await;
        info!(worker = %self.name, "worker stopped");
    }

    /// This slot's row in `workers`: what the cluster view shows. A failure is logged only; the
    /// row's heartbeat then ages and readers see the worker as silent.
    async fn record_state(&self, state: WorkerState, job_id: Option<&str>) {
        if let Err(error) = self
            .shared
            .database
            .worker_heartbeat(&self.name, state, job_id)
            .await
        {
            warn!(worker = %self.name, %error, "recording the worker's heartbeat failed");
        }
    }

    async fn run_job(&self, job: JobRecord) {
        let started = Instant::now();
        let outcome = self.attempt(&job).await;
        let Some(outcome) = outcome else {
            warn!("lease lost while running; another worker owns the job now");
            metrics::counter!("segsplat_job_outcomes_total", "kind" => job.kind.clone(),
                "outcome" => "lease_lost")
            .increment(1);
            return;
        };
        let outcome_label = match &outcome {
            AttemptOutcome::Succeeded => "succeeded",
            AttemptOutcome::Failed(_) => "failed",
            AttemptOutcome::Retry(_) => "retry",
            AttemptOutcome::Cancelled => "cancelled",
            AttemptOutcome::HandBack => "handed_back",
        };
        // Counted before the outcome is stored: a client that sees the job finish and then
        // scrapes /metrics finds the attempt there (it raced the store's write before).
        metrics::counter!("segsplat_job_outcomes_total", "kind" => job.kind.clone(),
            "outcome" => outcome_label)
        .increment(1);
        metrics::histogram!("segsplat_job_attempt_seconds", "kind" => job.kind.clone())
            .record(started.elapsed().as_secs_f64());
        match self.record_outcome(&job.id, &outcome).await {
            Ok(Some(finished)) => {
                info!(
                    outcome = outcome_label,
                    state = finished.state.as_str(),
                    elapsed_secs = started.elapsed().as_secs_f64(),
                    "attempt finished"
                );
                if finished.state == JobState::Succeeded && !self.shared.jobs.keep_final_checkpoint
                {
                    self.delete_checkpoints(&job.id).await;
                }
            }
            Ok(None) => warn!(
                outcome = outcome_label,
                "lease lost before the outcome was recorded"
            ),
            Err(error) => warn!(%error, "recording the outcome failed; the lease will expire"),
        }
        self.shared.bus.notify(&job.id);
    }

    /// Records how the attempt ended, retrying while the database is unreachable: the outcome
    /// (a finished training, say) is kept rather than left to a lease expiry and a re-run. The
    /// write stays conditional on this worker's lease, so a late retry cannot overwrite another
    /// worker's claim.
    async fn record_outcome(
        &self,
        job_id: &str,
        outcome: &AttemptOutcome,
    ) -> Result<Option<JobRecord>, StoreError> {
        let started = Instant::now();
        loop {
            match self
                .shared
                .database
                .finish_attempt(job_id, &self.name, outcome)
                .await
            {
                Err(error) if error.is_unavailable() && started.elapsed() < OUTCOME_RETRY => {
                    warn!(%error, "the database is unreachable; retrying to record the outcome");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
                result => return result,
            }
        }
    }

    /// Runs the handler; `None` when the lease was lost (nothing may be recorded then).
    async fn attempt(&self, job: &JobRecord) -> Option<AttemptOutcome> {
        let Some(handler) = self.shared.handlers.get(&job.kind).cloned() else {
            return Some(AttemptOutcome::Failed(format!(
                "no handler for job kind {:?} in this worker",
                job.kind
            )));
        };
        let work_dir = self
            .shared
            .scratch_dir
            .join(format!("job-{}-{}", job.id, job.attempts));
        let cancel = CancellationToken::new();
        let handler_shutdown = CancellationToken::new();
        let run = HandlerRun {
            shared: self.shared.clone(),
            job: job.clone(),
            handler,
            gpu: self.gpu.clone(),
            lease_owner: self.name.clone(),
            work_dir: work_dir.clone(),
            cancel: cancel.clone(),
            shutdown: handler_shutdown.clone(),
        };
        // Runs the handler, and again after each outage of the blob store, inside this claim.
        let mut handler_task = tokio::spawn(
            async move {
                let progress = run.progress();
                run_through_outages(|| run.once(), &progress, &run.cancel, &run.shutdown).await
            }
            .in_current_span(),
        );
        let heartbeat_every = Duration::from_secs_f64(self.shared.jobs.heartbeat_secs);
        let lease_ms = (self.shared.jobs.lease_secs * 1000.0).ceil() as i64;
        let mut heartbeat = tokio::time::interval(heartbeat_every);
        heartbeat.tick().await;
        // A cancel request for this job (from this process, or another through the database's
        // wake-ups) renews the heartbeat at once, which reads the cancel flag: the handler then
        // stops at its next step instead of up to `heartbeat_secs` later.
        let mut wakeups = self.shared.bus.subscribe();
        let mut bus_open = true;
        let mut lease_lost = false;
        let mut grace_deadline: Option<tokio::time::Instant> = None;
        let result = loop {
            let grace = async {
                match grace_deadline {
                    Some(deadline) => tokio::time::sleep_until(deadline).await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                joined = &mut handler_task => break Some(joined),
                woken = wakeups.recv(), if bus_open && !cancel.is_cancelled() => {
                    let asks_to_cancel = match woken {
                        Ok(woken) => JobEventBus::cancels(&woken, &job.id),
                        Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => true,
                        Err(tokio::sync::broadcast::error::RecvError::Closed) => {
                            bus_open = false;
                            false
                        }
                    };
                    if asks_to_cancel {
                        heartbeat.reset_immediately();
                    }
                }
                _ = heartbeat.tick() => {
                    self.record_state(WorkerState::Busy, Some(&job.id)).await;
                    match self.shared.database.heartbeat(&job.id, &self.name, lease_ms).await {
                        Ok(HeartbeatOutcome::Renewed { cancel_requested }) => {
                            if cancel_requested && !cancel.is_cancelled() {
                                info!("cancel requested; stopping at the next step boundary");
                                cancel.cancel();
                            }
                        }
                        Ok(HeartbeatOutcome::LeaseLost) => {
                            lease_lost = true;
                            cancel.cancel();
                        }
                        Err(error) => warn!(%error, "heartbeat failed; will retry"),
                    }
                }
                _ = self.shared.shutdown.cancelled(), if grace_deadline.is_none() => {
                    handler_shutdown.cancel();
                    grace_deadline = Some(tokio::time::Instant::now() + self.shared.shutdown_grace);
                }
                _ = grace => {
                    warn!("handler did not stop within the shutdown grace period; handing the job back");
                    handler_task.abort();
                    break None;
                }
            }
        };
        if let Err(error) = tokio::fs::remove_dir_all(&work_dir).await
            && error.kind() != std::io::ErrorKind::NotFound
        {
            warn!(%error, path = %work_dir.display(), "could not remove the job's scratch folder");
        }
        if lease_lost {
            return None;
        }
        Some(match result {
            None => AttemptOutcome::HandBack,
            Some(Ok(Ok(()))) => AttemptOutcome::Succeeded,
            Some(Ok(Err(JobFailure::Cancelled))) => AttemptOutcome::Cancelled,
            Some(Ok(Err(JobFailure::Interrupted))) => AttemptOutcome::HandBack,
            Some(Ok(Err(JobFailure::Fatal(message)))) => AttemptOutcome::Failed(message),
            Some(Ok(Err(JobFailure::Retryable(message) | JobFailure::Unavailable(message)))) => {
                AttemptOutcome::Retry(message)
            }
            Some(Err(join_error)) => {
                AttemptOutcome::Retry(format!("job handler crashed: {join_error}"))
            }
        })
    }

    /// Removes a finished job's checkpoints: they only serve a resume, and the last one of a
    /// training job can be hundreds of MB.
    async fn delete_checkpoints(&self, job_id: &str) {
        let blobs = self.shared.blobs.clone();
        let prefix = super::job_checkpoints_prefix(job_id);
        let deleted = tokio::task::spawn_blocking(move || blobs.delete_prefix(&prefix)).await;
        match deleted {
            Ok(Ok(_)) => {}
            Ok(Err(error)) => warn!(%error, "cannot delete the finished job's checkpoints"),
            Err(error) => warn!(%error, "deleting the finished job's checkpoints crashed"),
        }
    }
}
