//! `job_events`: the append-only history of each job (state changes, progress), replayed to
//! Server-Sent-Events subscribers.

use super::jobs::insert_event;
use super::sql::query;
use super::{Database, StoreError, now_ms};
use serde::Serialize;

/// A JSON column of `jobs` that an event of the same name also records.
#[derive(Debug, Clone, Copy)]
enum JobColumn {
    Progress,
    Settings,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct JobEventRecord {
    /// Increasing across all jobs; SSE uses it as the event id.
    pub id: i64,
    pub job_id: String,
    pub at_ms: i64,
    /// `state`, `progress`, `cancel_requested` or a handler's own kind.
    pub kind: String,
    pub payload: serde_json::Value,
}

impl Database {
    /// Records a progress event and makes it the job's current progress, if `owner` still holds
    /// the job's lease. Returns the event id, or `None` when the lease was lost.
    pub async fn record_progress(
        &self,
        job_id: &str,
        owner: &str,
        payload: &serde_json::Value,
    ) -> Result<Option<i64>, StoreError> {
        self.record_in_job(job_id, owner, JobColumn::Progress, payload)
            .await
    }

    /// Records the settings the job runs with (see [`super::jobs::JobRecord::settings`]) and a
    /// `settings` event carrying them, if `owner` still holds the job's lease. Returns the event
    /// id, or `None` when the lease was lost.
    pub async fn record_settings(
        &self,
        job_id: &str,
        owner: &str,
        settings: &serde_json::Value,
    ) -> Result<Option<i64>, StoreError> {
        self.record_in_job(job_id, owner, JobColumn::Settings, settings)
            .await
    }

    /// Stores `payload` in the job's `column` and appends it as an event of the column's kind,
    /// in one transaction, if `owner` holds the running job's lease.
    async fn record_in_job(
        &self,
        job_id: &str,
        owner: &str,
        column: JobColumn,
        payload: &serde_json::Value,
    ) -> Result<Option<i64>, StoreError> {
        let (column_name, kind) = match column {
            JobColumn::Progress => ("progress_json", "progress"),
            JobColumn::Settings => ("settings_json", "settings"),
        };
        let mut transaction = self.begin().await?;
        let updated = query(format!(
            "UPDATE jobs SET {column_name} = ?, updated_at_ms = ? \
             WHERE id = ? AND lease_owner = ? AND state = 'running'"
        ))
        .bind(payload.to_string())
        .bind(now_ms())
        .bind(job_id)
        .bind(owner)
        .execute(&mut transaction)
        .await?;
        if updated == 0 {
            return Ok(None);
        }
        let id = insert_event(&mut transaction, job_id, kind, payload).await?;
        transaction.commit().await?;
        Ok(Some(id))
    }

    /// Records an event of a handler's own `kind` (e.g. `warning`) for `job_id`, if `owner` still
    /// holds the job's lease. Returns the event id, or `None` when the lease was lost.
    pub async fn record_job_event(
        &self,
        job_id: &str,
        owner: &str,
        kind: &str,
        payload: &serde_json::Value,
    ) -> Result<Option<i64>, StoreError> {
        let mut transaction = self.begin().await?;
        let holds =
            query("SELECT 1 FROM jobs WHERE id = ? AND lease_owner = ? AND state = 'running'")
                .bind(job_id)
                .bind(owner)
                .fetch_optional(&mut transaction)
                .await?;
        if holds.is_none() {
            return Ok(None);
        }
        let id = insert_event(&mut transaction, job_id, kind, payload).await?;
        transaction.commit().await?;
        Ok(Some(id))
    }

    /// Events of `job_id` with id greater than `after_id`, oldest first, at most `limit`.
    pub async fn job_events_after(
        &self,
        job_id: &str,
        after_id: i64,
        limit: i64,
    ) -> Result<Vec<JobEventRecord>, StoreError> {
        let rows = query(
            "SELECT id, job_id, at_ms, kind, payload_json FROM job_events \
             WHERE job_id = ? AND id > ? ORDER BY id LIMIT ?",
        )
        .bind(job_id)
        .bind(after_id)
        .bind(limit)
        .fetch_all(self.sql())
        .await?;
        rows.iter()
            .map(|row| {
                let id: i64 = row.try_get("id")?;
                let payload_json: String = row.try_get("payload_json")?;
                let payload =
                    serde_json::from_str(&payload_json).map_err(|error| StoreError::Corrupt {
                        what: format!("job event {id}"),
                        message: error.to_string(),
                    })?;
                Ok(JobEventRecord {
                    id,
                    job_id: row.try_get("job_id")?,
                    at_ms: row.try_get("at_ms")?,
                    kind: row.try_get("kind")?,
                    payload,
                })
            })
            .collect()
    }
}
