//! Taking jobs back from workers that stopped: leases that ran out, and leases whose owner is
//! known to be gone (this process's own identity after a restart, or a dead process on this
//! host), which need not wait for the lease to run out.
//!
//! A reaped job is re-queued, or fails for good past its bounds: an expiry after the holder
//! made progress (saved a checkpoint, or reported steps past its first report;
//! `checkpointed_this_attempt`) counts against `max_lease_expiries` (the process, not the job,
//! failed), any other against `max_attempts`. A pending cancel cancels it.

use super::jobs::{COLUMNS, ExpiredLease, insert_state_event, job_from_row};
use super::sql::query;
use super::{Database, StoreError, now_ms};

impl Database {
    /// Re-queues running jobs whose lease ran out (their worker died or hung).
    pub async fn requeue_expired_leases(&self) -> Result<Vec<ExpiredLease>, StoreError> {
        let now = now_ms();
        self.reap_leases(|owner, expires_at_ms| {
            (expires_at_ms.is_some_and(|expires| expires < now))
                .then(|| format!("lease expired (worker {owner} stopped renewing)"))
        })
        .await
    }

    /// Re-queues, without waiting for their leases to run out, running jobs whose lease owner
    /// `is_gone` says has stopped (e.g. the process restarted with the same identity).
    pub async fn requeue_leases_of_gone_owners(
        &self,
        is_gone: impl Fn(&str) -> bool,
    ) -> Result<Vec<ExpiredLease>, StoreError> {
        self.reap_leases(|owner, _| {
            is_gone(owner).then(|| format!("worker {owner} is gone (its process restarted)"))
        })
        .await
    }

    /// Reaps every running job for which `reason(owner, lease_expires_at_ms)` gives a reason.
    async fn reap_leases(
        &self,
        reason: impl Fn(&str, Option<i64>) -> Option<String>,
    ) -> Result<Vec<ExpiredLease>, StoreError> {
        let now = now_ms();
        let mut transaction = self.begin().await?;
        let running =
            query("SELECT id, lease_owner, lease_expires_at_ms FROM jobs WHERE state = 'running'")
                .fetch_all(&mut transaction)
                .await?
                .iter()
                .map(
                    |row| -> Result<(String, Option<String>, Option<i64>), sqlx::Error> {
                        Ok((row.try_get(0)?, row.try_get(1)?, row.try_get(2)?))
                    },
                )
                .collect::<Result<Vec<_>, _>>()?;
        let mut results = Vec::new();
        for (job_id, previous_owner, expires_at_ms) in running {
            let owner_text = previous_owner.as_deref().unwrap_or("unknown");
            let Some(why) = reason(owner_text, expires_at_ms) else {
                continue;
            };
            // Conditional on the lease being the one just looked at, so a job renewed or
            // re-claimed meanwhile is left alone. SQLite evaluates every right-hand side on the
            // row as it was, so the CASEs below all see the old counters.
            let row = query(format!(
                "UPDATE jobs SET \
                   state = CASE WHEN cancel_requested THEN 'cancelled' \
                                WHEN checkpointed_this_attempt \
                                  THEN CASE WHEN lease_expiries + 1 >= max_lease_expiries \
                                            THEN 'failed' ELSE 'queued' END \
                                WHEN attempts >= max_attempts THEN 'failed' \
                                ELSE 'queued' END, \
                   error = CASE WHEN cancel_requested THEN NULL \
                                WHEN checkpointed_this_attempt \
                                  THEN ? || ' after the job made progress (steps or a checkpoint); ' || \
                                       CASE WHEN lease_expiries + 1 >= max_lease_expiries \
                                            THEN 'that happened ' || (lease_expiries + 1) || \
                                                 ' times (jobs.max_lease_expiries = ' || \
                                                 max_lease_expiries || '); giving up' \
                                            ELSE 're-queued to resume, not counted as an \
                                                  attempt' END \
                                WHEN attempts >= max_attempts \
                                  THEN ? || ' on attempt ' || attempts || ' of ' || \
                                       max_attempts || '; no attempts left' \
                                ELSE ? || '; re-queued' END, \
                   finished_at_ms = CASE WHEN cancel_requested \
                                           OR (checkpointed_this_attempt \
                                               AND lease_expiries + 1 >= max_lease_expiries) \
                                           OR (NOT checkpointed_this_attempt \
                                               AND attempts >= max_attempts) \
                                         THEN ? ELSE NULL END, \
                   attempts = attempts - CASE WHEN checkpointed_this_attempt THEN 1 ELSE 0 END, \
                   lease_expiries = lease_expiries + \
                                    CASE WHEN checkpointed_this_attempt THEN 1 ELSE 0 END, \
                   checkpointed_this_attempt = FALSE, \
                   lease_owner = NULL, lease_expires_at_ms = NULL, updated_at_ms = ? \
                 WHERE id = ? AND state = 'running' AND lease_owner IS NOT DISTINCT FROM ? \
                   AND lease_expires_at_ms IS NOT DISTINCT FROM ? \
                 RETURNING {COLUMNS}"
            ))
            .bind(&why)
            .bind(&why)
            .bind(&why)
            .bind(now)
            .bind(now)
            .bind(&job_id)
            .bind(&previous_owner)
            .bind(expires_at_ms)
            .fetch_optional(&mut transaction)
            .await?;
            if let Some(row) = row {
                let job = job_from_row(&row)?;
                insert_state_event(&mut transaction, &job).await?;
                results.push(ExpiredLease {
                    job_id,
                    previous_owner,
                    new_state: job.state,
                });
            }
        }
        transaction.commit().await?;
        Ok(results)
    }
}
