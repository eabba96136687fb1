//! `workers` rows: every worker slot of every process registers when it starts, heartbeats while
//! it runs (idle or busy, and on which job) and marks itself stopped when it stops, so any API
//! process can show the cluster's workers. A worker killed without stopping keeps its last
//! heartbeat, and readers tell it is gone by the heartbeat's age.

use serde::Serialize;

use super::sql::query;
use super::{Database, StoreError, now_ms};

/// Rows of stopped or silent workers are kept this long, then pruned when a worker registers.
const KEEP_GONE_MS: i64 = 24 * 3600 * 1000;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WorkerState {
    Idle,
    Busy,
    Stopped,
}

impl WorkerState {
    pub fn as_str(self) -> &'static str {
        match self {
            WorkerState::Idle => "idle",
            WorkerState::Busy => "busy",
            WorkerState::Stopped => "stopped",
        }
    }

    fn parse(text: &str) -> Option<Self> {
        [Self::Idle, Self::Busy, Self::Stopped]
            .into_iter()
            .find(|state| state.as_str() == text)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorkerRecord {
    /// The slot's lease-owner name, `{instance}/{slot}`.
    pub id: String,
    pub instance: String,
    /// The GPU adapter's name, or `cpu`.
    pub device: String,
    /// Job kinds it takes.
    pub kinds: Vec<String>,
    pub state: WorkerState,
    pub job_id: Option<String>,
    pub started_at_ms: i64,
    pub heartbeat_at_ms: i64,
}

impl Database {
    /// Registers (or re-registers) a worker slot as idle, and prunes long-gone workers.
    pub async fn register_worker(
        &self,
        id: &str,
        instance: &str,
        device: &str,
        kinds: &[&str],
    ) -> Result<(), StoreError> {
        let now = now_ms();
        let kinds_json = serde_json::to_string(kinds).map_err(|error| StoreError::Corrupt {
            what: "worker kinds".to_string(),
            message: error.to_string(),
        })?;
        query(
            "INSERT INTO workers (id, instance, device, kinds_json, state, job_id, started_at_ms, \
             heartbeat_at_ms) VALUES (?, ?, ?, ?, 'idle', NULL, ?, ?) \
             ON CONFLICT (id) DO UPDATE SET instance = excluded.instance, \
             device = excluded.device, kinds_json = excluded.kinds_json, state = 'idle', \
             job_id = NULL, started_at_ms = excluded.started_at_ms, \
             heartbeat_at_ms = excluded.heartbeat_at_ms",
        )
        .bind(id)
        .bind(instance)
        .bind(device)
        .bind(kinds_json)
        .bind(now)
        .bind(now)
        .execute(self.sql())
        .await?;
        query("DELETE FROM workers WHERE heartbeat_at_ms < ?")
            .bind(now - KEEP_GONE_MS)
            .execute(self.sql())
            .await?;
        Ok(())
    }

    /// Records the worker's state (and job, when busy) with a fresh heartbeat.
    pub async fn worker_heartbeat(
        &self,
        id: &str,
        state: WorkerState,
        job_id: Option<&str>,
    ) -> Result<(), StoreError> {
        query("UPDATE workers SET state = ?, job_id = ?, heartbeat_at_ms = ? WHERE id = ?")
            .bind(state.as_str())
            .bind(job_id)
            .bind(now_ms())
            .bind(id)
            .execute(self.sql())
            .await?;
        Ok(())
    }

    /// Every registered worker, newest heartbeat first.
    pub async fn list_workers(&self) -> Result<Vec<WorkerRecord>, StoreError> {
        let rows = query(
            "SELECT id, instance, device, kinds_json, state, job_id, started_at_ms, \
             heartbeat_at_ms FROM workers ORDER BY heartbeat_at_ms DESC, id",
        )
        .fetch_all(self.sql())
        .await?;
        rows.iter()
            .map(|row| {
                let corrupt = |message: String| StoreError::Corrupt {
                    what: "worker".to_string(),
                    message,
                };
                let state: String = row.try_get("state")?;
                let kinds_json: String = row.try_get("kinds_json")?;
                Ok(WorkerRecord {
                    id: row.try_get("id")?,
                    instance: row.try_get("instance")?,
                    device: row.try_get("device")?,
                    kinds: serde_json::from_str(&kinds_json)
                        .map_err(|error| corrupt(error.to_string()))?,
                    state: WorkerState::parse(&state)
                        .ok_or_else(|| corrupt(format!("unknown state {state:?}")))?,
                    job_id: row.try_get("job_id")?,
                    started_at_ms: row.try_get("started_at_ms")?,
                    heartbeat_at_ms: row.try_get("heartbeat_at_ms")?,
                })
            })
            .collect()
    }
}
