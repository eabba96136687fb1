//! Progress from a running job: stored as `progress` events (and the job's current progress),
//! announced to SSE subscribers, with an ETA estimated from the current stage's step rate.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::JobEventBus;
use crate::store::{Database, StoreError};

/// One progress report from a handler.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// e.g. `segment`, `train`, `embed`.
    pub stage: String,
    pub step: u64,
    pub total_steps: u64,
    /// Named numbers worth plotting (loss, Gaussian count, PSNR, ...).
    #[serde(default)]
    pub metrics: BTreeMap<String, f64>,
    /// Seconds left in this stage, estimated from its step rate so far.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eta_secs: Option<f64>,
}

/// Where the current stage started, to turn steps into a rate.
#[derive(Debug)]
struct StageClock {
    stage: String,
    started: Instant,
    first_step: u64,
}

#[derive(Debug, Clone)]
pub struct ProgressReporter {
    database: Database,
    bus: JobEventBus,
    job_id: String,
    lease_owner: String,
    clock: Arc<Mutex<Option<StageClock>>>,
    /// The last reported (stage, step), to count steps done for `segsplat_job_steps_total`.
    last_step: Arc<Mutex<Option<(String, u64)>>>,
    /// Whether steps done under this lease were noted in the job's row already.
    steps_noted: Arc<AtomicBool>,
}

impl ProgressReporter {
    pub(crate) fn new(
        database: Database,
        bus: JobEventBus,
        job_id: String,
        lease_owner: String,
    ) -> Self {
        Self {
            database,
            bus,
            job_id,
            lease_owner,
            clock: Arc::new(Mutex::new(None)),
            last_step: Arc::new(Mutex::new(None)),
            steps_noted: Arc::new(AtomicBool::new(false)),
        }
    }

    /// Records `progress` (filling in the ETA when the handler gave none). Returns false when
    /// this worker no longer holds the job's lease.
    pub async fn report(&self, mut progress: Progress) -> Result<bool, StoreError> {
        if progress.eta_secs.is_none() {
            progress.eta_secs = self.estimate_eta(&progress);
        }
        let payload = serde_json::to_value(&progress).map_err(|error| StoreError::Corrupt {
            what: "progress".to_string(),
            message: error.to_string(),
        })?;
        // Steps past this run's first report are progress, as a checkpoint is: a crash of the
        // process after them is not counted as an attempt (issue 39: a host that crashes
        // between checkpoints must not starve a job that trains on each life). Noted before
        // the report is stored, so whoever sees these steps (an operator, a test that then
        // kills the host) finds them counted; fired after it, a kill could beat the note.
        let done = self.steps_since_last_report(&progress);
        if done > 0 && !self.steps_noted.load(Ordering::Relaxed) {
            match self
                .database
                .record_checkpoint(&self.job_id, &self.lease_owner)
                .await
            {
                Ok(_) => self.steps_noted.store(true, Ordering::Relaxed),
                Err(error) => {
                    tracing::warn!(%error, job_id = %self.job_id, "cannot note the job's steps")
                }
            }
        }
        let recorded = self
            .database
            .record_progress(&self.job_id, &self.lease_owner, &payload)
            .await?;
        if recorded.is_some() {
            self.bus.notify(&self.job_id);
            self.count_steps(&progress, done);
        }
        Ok(recorded.is_some())
    }

    /// Adds `done`, the steps since the last report of the same stage, to
    /// `segsplat_job_steps_total{worker, stage}`, so dashboards show steps/s per worker, and
    /// makes `progress` the last report.
    fn count_steps(&self, progress: &Progress, done: u64) {
        let Ok(mut last) = self.last_step.lock() else {
            return;
        };
        *last = Some((progress.stage.clone(), progress.step));
        metrics::counter!("segsplat_job_steps_total", "worker" => self.lease_owner.clone(),
            "stage" => progress.stage.clone())
        .increment(done);
    }

    /// Steps `progress` is past the last recorded report of the same stage (0 for a first
    /// report or a new stage).
    fn steps_since_last_report(&self, progress: &Progress) -> u64 {
        let Ok(last) = self.last_step.lock() else {
            return 0;
        };
        match last.as_ref() {
            Some((stage, step)) if *stage == progress.stage => progress.step.saturating_sub(*step),
            _ => 0,
        }
    }

    /// [`Self::report`] from blocking code (inside `spawn_blocking`).
    pub fn report_blocking(&self, progress: Progress) -> Result<bool, StoreError> {
        tokio::runtime::Handle::current().block_on(self.report(progress))
    }

    /// Records a `warning` event (`{"stage", "message"}`) for the job, e.g. a config whose stage
    /// cannot happen. Returns false when this worker no longer holds the job's lease.
    pub async fn warn(&self, stage: &str, message: &str) -> Result<bool, StoreError> {
        let payload = serde_json::json!({ "stage": stage, "message": message });
        self.record("warning", &payload).await
    }

    /// Records a `resumed` event (`{"stage", "from_step"}`): this attempt continues from a
    /// checkpoint an earlier attempt saved (after a crash, a lost lease or a shutdown).
    pub fn resumed_blocking(&self, stage: &str, from_step: u64) -> Result<bool, StoreError> {
        let payload = serde_json::json!({ "stage": stage, "from_step": from_step });
        tokio::runtime::Handle::current().block_on(self.record("resumed", &payload))
    }

    /// Records an `undistorted` event (`{"stage", "message", "lenses"}`): the scene's frames of
    /// these distorted camera models were undistorted to pinhole cameras as they were loaded.
    pub fn undistorted_blocking(
        &self,
        stage: &str,
        message: &str,
        lenses: &serde_json::Value,
    ) -> Result<bool, StoreError> {
        let payload = serde_json::json!({ "stage": stage, "message": message, "lenses": lenses });
        tokio::runtime::Handle::current().block_on(self.record("undistorted", &payload))
    }

    /// Records the settings the job runs with, resolved from the scene, in its record and as a
    /// `settings` event, from blocking code. Returns false when this worker no longer holds the
    /// job's lease.
    pub fn settings_blocking(&self, settings: &serde_json::Value) -> Result<bool, StoreError> {
        let recorded = tokio::runtime::Handle::current().block_on(
            self.database
                .record_settings(&self.job_id, &self.lease_owner, settings),
        )?;
        if recorded.is_some() {
            self.bus.notify(&self.job_id);
        }
        Ok(recorded.is_some())
    }

    async fn record(&self, kind: &str, payload: &serde_json::Value) -> Result<bool, StoreError> {
        let recorded = self
            .database
            .record_job_event(&self.job_id, &self.lease_owner, kind, payload)
            .await?;
        if recorded.is_some() {
            self.bus.notify(&self.job_id);
        }
        Ok(recorded.is_some())
    }

    /// [`Self::warn`] from blocking code (inside `spawn_blocking`).
    pub fn warn_blocking(&self, stage: &str, message: &str) -> Result<bool, StoreError> {
        tokio::runtime::Handle::current().block_on(self.warn(stage, message))
    }

    /// [`Self::warn`] without waiting for it, callable from async and blocking code alike; the
    /// event lands shortly after. For warnings raised where the caller cannot block (a handler
    /// running on the runtime itself).
    pub fn warn_detached(&self, stage: &str, message: &str) {
        let Ok(runtime) = tokio::runtime::Handle::try_current() else {
            return;
        };
        let reporter = self.clone();
        let (stage, message) = (stage.to_string(), message.to_string());
        runtime.spawn(async move {
            if let Err(error) = reporter.warn(&stage, &message).await {
                tracing::warn!(%error, "warning event not recorded");
            }
        });
    }

    /// Notes in the job's row that this lease holder made progress (saved a checkpoint, or
    /// reported steps past its first report), so a lease expiry after it counts as progress
    /// rather than an attempt. Fire and forget, callable from async
    /// and blocking code alike: the note is an optimisation of retry accounting, and a lost one
    /// only means that expiry counts as an attempt.
    pub fn note_checkpoint(&self) {
        let Ok(runtime) = tokio::runtime::Handle::try_current() else {
            return;
        };
        let database = self.database.clone();
        let job_id = self.job_id.clone();
        let owner = self.lease_owner.clone();
        runtime.spawn(async move {
            if let Err(error) = database.record_checkpoint(&job_id, &owner).await {
                tracing::warn!(%error, %job_id, "cannot note the job's checkpoint");
            }
        });
    }

    fn estimate_eta(&self, progress: &Progress) -> Option<f64> {
        let mut clock = self.clock.lock().ok()?;
        let restart = clock.as_ref().is_none_or(|current| {
            current.stage != progress.stage || progress.step < current.first_step
        });
        if restart {
            *clock = Some(StageClock {
                stage: progress.stage.clone(),
                started: Instant::now(),
                first_step: progress.step,
            });
            return None;
        }
        let current = clock.as_ref()?;
        let steps_done = progress.step.saturating_sub(current.first_step);
        if steps_done == 0 || progress.total_steps < progress.step {
            return None;
        }
        let secs_per_step = current.started.elapsed().as_secs_f64() / steps_done as f64;
        Some(secs_per_step * (progress.total_steps - progress.step) as f64)
    }
}
