//! The durable job queue in the `jobs` table.
//!
//! A job is claimed atomically (one conditional `UPDATE ... RETURNING` on the oldest queued job of
//! the kinds a worker runs), which takes a lease owned by the worker and counts an attempt. The
//! worker renews the lease by heartbeat; every later transition is conditional on the worker
//! still owning the lease, so a worker that lost its lease cannot overwrite the job. Expired
//! leases are re-queued (or failed past their bounds) by `lease_reaping`.
//! Every state change appends a `state` event to `job_events` in the same transaction.
//!
//! On Postgres the claim's inner select becomes `... LIMIT 1 FOR UPDATE SKIP LOCKED`.

use serde::{Deserialize, Serialize};

use super::sql::{DbRow, Tx, query};
use super::tenancy::{Caller, visible};
use super::wakeups::{announce_cancel, announce_event};
use super::{Backend, Database, StoreError, now_ms};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobState {
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Succeeded,
        JobState::Failed,
        JobState::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    pub fn parse(text: &str) -> Option<JobState> {
        JobState::ALL
            .into_iter()
            .find(|state| state.as_str() == text)
    }

    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobState::Succeeded | JobState::Failed | JobState::Cancelled
        )
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct JobRecord {
    pub id: String,
    pub scene_id: String,
    pub kind: String,
    pub state: JobState,
    pub config: serde_json::Value,
    /// Claims so far, including the running one.
    pub attempts: u32,
    pub max_attempts: u32,
    /// Lease expiries after which the job had saved a newer checkpoint; they are not counted
    /// as attempts.
    pub lease_expiries: u32,
    /// Such expiries before the job fails for good.
    pub max_lease_expiries: u32,
    /// Whether the current lease holder has saved a checkpoint.
    pub checkpointed_this_attempt: bool,
    pub lease_owner: Option<String>,
    pub lease_expires_at_ms: Option<i64>,
    pub cancel_requested: bool,
    pub error: Option<String>,
    /// The latest progress event's payload.
    pub progress: Option<serde_json::Value>,
    /// The settings the job runs with, once its worker has resolved them from the scene
    /// (`config` keeps what it was created with).
    pub settings: Option<serde_json::Value>,
    pub created_at_ms: i64,
    pub updated_at_ms: i64,
    pub started_at_ms: Option<i64>,
    pub finished_at_ms: Option<i64>,
    /// Its scene's tenant ([`super::tenancy`]).
    pub tenant: String,
}

/// How a worker's attempt at a job ended.
#[derive(Debug, Clone, PartialEq)]
pub enum AttemptOutcome {
    Succeeded,
    /// Fails the job for good.
    Failed(String),
    /// Re-queues the job, or fails it when its attempts are used up.
    Retry(String),
    Cancelled,
    /// The worker is shutting down: back to the queue without counting the attempt.
    HandBack,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeartbeatOutcome {
    Renewed {
        cancel_requested: bool,
    },
    /// Another worker or the lease reaper took the job; stop working on it.
    LeaseLost,
}

#[derive(Debug, Clone, PartialEq)]
pub enum CancelOutcome {
    /// The job was queued and is now cancelled.
    Cancelled(JobRecord),
    /// The job is running; its worker stops at the next step boundary.
    Requested(JobRecord),
    AlreadyFinished(JobRecord),
    NotFound,
}

/// When a job fails for good: `max_attempts` counts claims that ended in an error or a lease
/// expiry without a new checkpoint; `max_lease_expiries` counts lease expiries after which the
/// job had saved a newer checkpoint (the process died while the job progressed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AttemptBounds {
    pub max_attempts: u32,
    pub max_lease_expiries: u32,
}

/// A job whose lease expired and what became of it.
#[derive(Debug, Clone, PartialEq)]
pub struct ExpiredLease {
    pub job_id: String,
    pub previous_owner: Option<String>,
    pub new_state: JobState,
}

pub(super) const COLUMNS: &str = "id, scene_id, kind, state, config_json, attempts, max_attempts, \
    lease_expiries, max_lease_expiries, checkpointed_this_attempt, lease_owner, lease_expires_at_ms, cancel_requested, error, progress_json, settings_json, \
    created_at_ms, updated_at_ms, started_at_ms, finished_at_ms, tenant";

fn corrupt(job_id: &str, what: &str, message: impl ToString) -> StoreError {
    StoreError::Corrupt {
        what: format!("{what} of job {job_id}"),
        message: message.to_string(),
    }
}

pub(super) fn job_from_row(row: &DbRow) -> Result<JobRecord, StoreError> {
    let id: String = row.try_get("id")?;
    let state_text: String = row.try_get("state")?;
    let state = JobState::parse(&state_text)
        .ok_or_else(|| corrupt(&id, "state", format!("unknown state {state_text:?}")))?;
    let config_json: String = row.try_get("config_json")?;
    let config =
        serde_json::from_str(&config_json).map_err(|error| corrupt(&id, "config", error))?;
    let progress_json: Option<String> = row.try_get("progress_json")?;
    let progress = progress_json
        .map(|text| serde_json::from_str(&text))
        .transpose()
        .map_err(|error| corrupt(&id, "progress", error))?;
    let settings_json: Option<String> = row.try_get("settings_json")?;
    let settings = settings_json
        .map(|text| serde_json::from_str(&text))
        .transpose()
        .map_err(|error| corrupt(&id, "settings", error))?;
    let attempts: i64 = row.try_get("attempts")?;
    let max_attempts: i64 = row.try_get("max_attempts")?;
    let lease_expiries: i64 = row.try_get("lease_expiries")?;
    let max_lease_expiries: i64 = row.try_get("max_lease_expiries")?;
    Ok(JobRecord {
        scene_id: row.try_get("scene_id")?,
        kind: row.try_get("kind")?,
        state,
        config,
        attempts: attempts.max(0) as u32,
        max_attempts: max_attempts.max(0) as u32,
        lease_expiries: lease_expiries.max(0) as u32,
        max_lease_expiries: max_lease_expiries.max(0) as u32,
        checkpointed_this_attempt: row.try_get("checkpointed_this_attempt")?,
        lease_owner: row.try_get("lease_owner")?,
        lease_expires_at_ms: row.try_get("lease_expires_at_ms")?,
        cancel_requested: row.try_get("cancel_requested")?,
        error: row.try_get("error")?,
        progress,
        settings,
        created_at_ms: row.try_get("created_at_ms")?,
        updated_at_ms: row.try_get("updated_at_ms")?,
        started_at_ms: row.try_get("started_at_ms")?,
        finished_at_ms: row.try_get("finished_at_ms")?,
        tenant: row.try_get("tenant")?,
        id,
    })
}

/// Appends an event inside `transaction`; returns its id.
pub(super) async fn insert_event(
    transaction: &mut Tx,
    job_id: &str,
    kind: &str,
    payload: &serde_json::Value,
) -> Result<i64, StoreError> {
    append_event(transaction, job_id, kind, payload, false).await
}

/// Appends the job's new state as an event; a job left queued also wakes idle workers of other
/// processes ([`super::wakeups`]).
pub(super) async fn insert_state_event(
    transaction: &mut Tx,
    job: &JobRecord,
) -> Result<i64, StoreError> {
    let payload = serde_json::json!({
        "state": job.state,
        "attempts": job.attempts,
        "max_attempts": job.max_attempts,
        "error": job.error,
    });
    append_event(
        transaction,
        &job.id,
        "state",
        &payload,
        job.state == JobState::Queued,
    )
    .await
}

async fn append_event(
    transaction: &mut Tx,
    job_id: &str,
    kind: &str,
    payload: &serde_json::Value,
    job_is_queued: bool,
) -> Result<i64, StoreError> {
    let id: i64 = query(
        "INSERT INTO job_events (job_id, at_ms, kind, payload_json) VALUES (?, ?, ?, ?) \
         RETURNING id",
    )
    .bind(job_id)
    .bind(now_ms())
    .bind(kind)
    .bind(payload.to_string())
    .fetch_one(&mut *transaction)
    .await?
    .try_get(0)?;
    announce_event(transaction, job_id, job_is_queued).await?;
    Ok(id)
}

impl Database {
    /// Queues a job for an existing scene `caller` sees; `None` when there is no such scene.
    /// The job belongs to the scene's tenant (also when an admin queues it).
    pub async fn insert_job(
        &self,
        scene_id: &str,
        kind: &str,
        config: &serde_json::Value,
        bounds: AttemptBounds,
        caller: &Caller,
    ) -> Result<Option<JobRecord>, StoreError> {
        let id = uuid::Uuid::now_v7().to_string();
        let now = now_ms();
        let mut transaction = self.begin().await?;
        let row = query(format!(
            "INSERT INTO jobs (id, scene_id, kind, state, config_json, attempts, max_attempts, \
             max_lease_expiries, cancel_requested, created_at_ms, updated_at_ms, tenant) \
             SELECT ?, ?, ?, 'queued', ?, 0, ?, ?, FALSE, ?, ?, tenant FROM scenes \
             WHERE id = ? AND {} RETURNING {COLUMNS}",
            visible("tenant")
        ))
        .bind(&id)
        .bind(scene_id)
        .bind(kind)
        .bind(config.to_string())
        .bind(i64::from(bounds.max_attempts))
        .bind(i64::from(bounds.max_lease_expiries))
        .bind(now)
        .bind(now)
        .bind(scene_id)
        .bind(caller.admin)
        .bind(&caller.tenant)
        .fetch_optional(&mut transaction)
        .await?;
        let Some(row) = row else {
            return Ok(None);
        };
        let job = job_from_row(&row)?;
        insert_state_event(&mut transaction, &job).await?;
        transaction.commit().await?;
        Ok(Some(job))
    }

    /// The job, when it exists and `caller` sees its tenant.
    pub async fn get_job(
        &self,
        id: &str,
        caller: &Caller,
    ) -> Result<Option<JobRecord>, StoreError> {
        let row = query(format!(
            "SELECT {COLUMNS} FROM jobs WHERE id = ? AND {}",
            visible("tenant")
        ))
        .bind(id)
        .bind(caller.admin)
        .bind(&caller.tenant)
        .fetch_optional(self.sql())
        .await?;
        row.as_ref().map(job_from_row).transpose()
    }

    /// The jobs `caller` sees (in `state`, when given), oldest first.
    pub async fn list_jobs(
        &self,
        state: Option<JobState>,
        caller: &Caller,
    ) -> Result<Vec<JobRecord>, StoreError> {
        let rows = query(format!(
            "SELECT {COLUMNS} FROM jobs WHERE (? IS NULL OR state = ?) AND {} \
             ORDER BY created_at_ms, id",
            visible("tenant")
        ))
        .bind(state.map(JobState::as_str))
        .bind(state.map(JobState::as_str))
        .bind(caller.admin)
        .bind(&caller.tenant)
        .fetch_all(self.sql())
        .await?;
        rows.iter().map(job_from_row).collect()
    }

    /// The scene's most recently finished successful job of `kind`: the one whose results a
    /// scene currently serves (its object table was written last).
    pub async fn latest_succeeded_job(
        &self,
        scene_id: &str,
        kind: &str,
    ) -> Result<Option<JobRecord>, StoreError> {
        let row = query(format!(
            "SELECT {COLUMNS} FROM jobs WHERE scene_id = ? AND kind = ? AND state = 'succeeded' \
             ORDER BY updated_at_ms DESC, id DESC LIMIT 1"
        ))
        .bind(scene_id)
        .bind(kind)
        .fetch_optional(self.sql())
        .await?;
        row.as_ref().map(job_from_row).transpose()
    }

    /// Jobs per state, for the queue-depth gauges.
    pub async fn job_counts_by_state(&self) -> Result<Vec<(JobState, i64)>, StoreError> {
        let rows = query("SELECT state, COUNT(*) FROM jobs GROUP BY state")
            .fetch_all(self.sql())
            .await?
            .iter()
            .map(|row| Ok((row.try_get::<String, _>(0)?, row.try_get::<i64, _>(1)?)))
            .collect::<Result<Vec<_>, sqlx::Error>>()?;
        Ok(JobState::ALL
            .into_iter()
            .map(|state| {
                let count = rows
                    .iter()
                    .find(|(name, _)| name == state.as_str())
                    .map_or(0, |(_, count)| *count);
                (state, count)
            })
            .collect())
    }

    /// Leases the oldest queued job of one of `kinds` to `owner` for `lease_ms`, counting an
    /// attempt. `None` when nothing is queued.
    pub async fn claim_job(
        &self,
        owner: &str,
        kinds: &[&str],
        lease_ms: i64,
    ) -> Result<Option<JobRecord>, StoreError> {
        if kinds.is_empty() {
            return Ok(None);
        }
        let now = now_ms();
        let placeholders = vec!["?"; kinds.len()].join(", ");
        // On Postgres, concurrent claimers skip a row another claimer has locked and take the
        // next one; SQLite serialises writers, so the plain select is already exclusive.
        let skip_locked = match self.backend() {
            Backend::Postgres => " FOR UPDATE SKIP LOCKED",
            Backend::Sqlite => "",
        };
        let statement = format!(
            "UPDATE jobs SET state = 'running', lease_owner = ?, lease_expires_at_ms = ?, \
             attempts = attempts + 1, checkpointed_this_attempt = FALSE, updated_at_ms = ?, \
             started_at_ms = COALESCE(started_at_ms, ?), error = NULL \
             WHERE id = (SELECT id FROM jobs WHERE state = 'queued' AND kind IN ({placeholders}) \
                         ORDER BY created_at_ms, id LIMIT 1{skip_locked}) \
               AND state = 'queued' \
             RETURNING {COLUMNS}"
        );
        let mut transaction = self.begin().await?;
        let mut claim = query(statement)
            .bind(owner)
            .bind(now + lease_ms)
            .bind(now)
            .bind(now);
        for kind in kinds {
            claim = claim.bind(*kind);
        }
        let Some(row) = claim.fetch_optional(&mut transaction).await? else {
            return Ok(None);
        };
        let job = job_from_row(&row)?;
        insert_state_event(&mut transaction, &job).await?;
        transaction.commit().await?;
        Ok(Some(job))
    }

    /// Extends `owner`'s lease on a running job and reports whether cancel was requested.
    pub async fn heartbeat(
        &self,
        job_id: &str,
        owner: &str,
        lease_ms: i64,
    ) -> Result<HeartbeatOutcome, StoreError> {
        let now = now_ms();
        let cancel_requested: Option<bool> = query(
            "UPDATE jobs SET lease_expires_at_ms = ?, updated_at_ms = ? \
             WHERE id = ? AND lease_owner = ? AND state = 'running' RETURNING cancel_requested",
        )
        .bind(now + lease_ms)
        .bind(now)
        .bind(job_id)
        .bind(owner)
        .fetch_optional(self.sql())
        .await?
        .map(|row| row.try_get(0))
        .transpose()?;
        Ok(match cancel_requested {
            Some(cancel_requested) => HeartbeatOutcome::Renewed { cancel_requested },
            None => HeartbeatOutcome::LeaseLost,
        })
    }

    /// Records how `owner`'s attempt ended. `None` when `owner` no longer holds the lease (the
    /// job was re-queued meanwhile); the outcome is then dropped.
    pub async fn finish_attempt(
        &self,
        job_id: &str,
        owner: &str,
        outcome: &AttemptOutcome,
    ) -> Result<Option<JobRecord>, StoreError> {
        let now = now_ms();
        let (state_sql, attempts_sql, error, finished) = match outcome {
            AttemptOutcome::Succeeded => ("'succeeded'", "attempts", None, Some(now)),
            AttemptOutcome::Failed(message) => {
                ("'failed'", "attempts", Some(message.clone()), Some(now))
            }
            AttemptOutcome::Cancelled => ("'cancelled'", "attempts", None, Some(now)),
            AttemptOutcome::Retry(message) => (
                "CASE WHEN attempts >= max_attempts THEN 'failed' ELSE 'queued' END",
                "attempts",
                Some(message.clone()),
                None,
            ),
            AttemptOutcome::HandBack => ("'queued'", "attempts - 1", None, None),
        };
        let statement = format!(
            "UPDATE jobs SET state = {state_sql}, attempts = {attempts_sql}, lease_owner = NULL, \
             lease_expires_at_ms = NULL, error = ?, updated_at_ms = ?, finished_at_ms = ? \
             WHERE id = ? AND lease_owner = ? AND state = 'running' RETURNING {COLUMNS}"
        );
        let mut transaction = self.begin().await?;
        let row = query(statement)
            .bind(error)
            .bind(now)
            .bind(finished)
            .bind(job_id)
            .bind(owner)
            .fetch_optional(&mut transaction)
            .await?;
        let Some(row) = row else {
            return Ok(None);
        };
        let mut job = job_from_row(&row)?;
        if job.state == JobState::Failed && job.finished_at_ms.is_none() {
            job = self
                .mark_finished(&mut transaction, &job.id, now)
                .await?
                .unwrap_or(job);
        }
        insert_state_event(&mut transaction, &job).await?;
        transaction.commit().await?;
        Ok(Some(job))
    }

    async fn mark_finished(
        &self,
        transaction: &mut Tx,
        job_id: &str,
        now: i64,
    ) -> Result<Option<JobRecord>, StoreError> {
        let row = query(format!(
            "UPDATE jobs SET finished_at_ms = ? WHERE id = ? RETURNING {COLUMNS}"
        ))
        .bind(now)
        .bind(job_id)
        .fetch_optional(&mut *transaction)
        .await?;
        row.as_ref().map(job_from_row).transpose()
    }

    /// Notes that `owner`, still holding the lease, saved a checkpoint of the job: if this
    /// attempt's lease later expires, the job made progress and the expiry is not counted as an
    /// attempt. Returns false when `owner` no longer holds the lease.
    pub async fn record_checkpoint(&self, job_id: &str, owner: &str) -> Result<bool, StoreError> {
        let updated = query(
            "UPDATE jobs SET checkpointed_this_attempt = TRUE \
             WHERE id = ? AND lease_owner = ? AND state = 'running'",
        )
        .bind(job_id)
        .bind(owner)
        .execute(self.sql())
        .await?;
        Ok(updated > 0)
    }

    /// Cancels a queued job at once, or flags a running one for its worker. Another tenant's
    /// job is [`CancelOutcome::NotFound`] (a job never changes tenant, so checking first is
    /// enough).
    pub async fn request_cancel(
        &self,
        job_id: &str,
        caller: &Caller,
    ) -> Result<CancelOutcome, StoreError> {
        if self.get_job(job_id, caller).await?.is_none() {
            return Ok(CancelOutcome::NotFound);
        }
        let now = now_ms();
        let mut transaction = self.begin().await?;
        let row = query(format!(
            "UPDATE jobs SET state = 'cancelled', cancel_requested = TRUE, updated_at_ms = ?, \
             finished_at_ms = ? WHERE id = ? AND state = 'queued' RETURNING {COLUMNS}"
        ))
        .bind(now)
        .bind(now)
        .bind(job_id)
        .fetch_optional(&mut transaction)
        .await?;
        if let Some(row) = row {
            let job = job_from_row(&row)?;
            insert_state_event(&mut transaction, &job).await?;
            transaction.commit().await?;
            return Ok(CancelOutcome::Cancelled(job));
        }
        let row = query(format!(
            "UPDATE jobs SET cancel_requested = TRUE, updated_at_ms = ? \
             WHERE id = ? AND state = 'running' RETURNING {COLUMNS}"
        ))
        .bind(now)
        .bind(job_id)
        .fetch_optional(&mut transaction)
        .await?;
        if let Some(row) = row {
            let job = job_from_row(&row)?;
            insert_event(
                &mut transaction,
                job_id,
                "cancel_requested",
                &serde_json::json!({}),
            )
            .await?;
            announce_cancel(&mut transaction, job_id).await?;
            transaction.commit().await?;
            return Ok(CancelOutcome::Requested(job));
        }
        transaction.commit().await?;
        Ok(match self.get_job(job_id, caller).await? {
            Some(job) => CancelOutcome::AlreadyFinished(job),
            None => CancelOutcome::NotFound,
        })
    }
}
