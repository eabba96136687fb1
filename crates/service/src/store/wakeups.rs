//! Cross-process wake-ups on PostgreSQL (LISTEN/NOTIFY): a transaction that appends a job event
//! notifies `segsplat_job_events` with the job id, one that leaves a job queued also notifies
//! `segsplat_jobs_queued`, and a cancel of a running job notifies `segsplat_job_cancels` (so its
//! worker, wherever it runs, stops at its next step). Postgres delivers them at commit, to every process
//! listening, so idle workers claim at once and event followers on other API processes see
//! progress without polling. SQLite has no such channel: there, processes wake each other only
//! within one process and otherwise poll (`jobs.poll_interval_ms`), which stays the safety net
//! on both.

use std::time::Duration;

use sqlx::postgres::PgListener;

use super::sql::{Tx, query};
use super::{Database, StoreError};

const JOBS_QUEUED: &str = "segsplat_jobs_queued";
const JOB_EVENTS: &str = "segsplat_job_events";
const JOB_CANCELS: &str = "segsplat_job_cancels";

/// What another process announced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Wakeup {
    /// A job became claimable.
    JobQueued,
    /// The job has new events.
    JobEvent(String),
    /// A cancel was requested for the (running) job.
    JobCancel(String),
    /// The listening connection was lost and re-established; announcements in between were
    /// missed, so every waiter should look again.
    Missed,
}

/// Queues the notification that a running job's cancel was requested (Postgres only).
pub(super) async fn announce_cancel(transaction: &mut Tx, job_id: &str) -> Result<(), StoreError> {
    if matches!(transaction, Tx::Postgres(_)) {
        query("SELECT pg_notify(?, ?)")
            .bind(JOB_CANCELS)
            .bind(job_id)
            .execute(&mut *transaction)
            .await?;
    }
    Ok(())
}

/// Queues the notifications for a new event of `job_id` inside `transaction` (Postgres only).
pub(super) async fn announce_event(
    transaction: &mut Tx,
    job_id: &str,
    job_is_queued: bool,
) -> Result<(), StoreError> {
    if !matches!(transaction, Tx::Postgres(_)) {
        return Ok(());
    }
    query("SELECT pg_notify(?, ?)")
        .bind(JOB_EVENTS)
        .bind(job_id)
        .execute(&mut *transaction)
        .await?;
    if job_is_queued {
        query("SELECT pg_notify(?, '')")
            .bind(JOBS_QUEUED)
            .execute(&mut *transaction)
            .await?;
    }
    Ok(())
}

/// A process's subscription to the wake-up channels.
pub struct WakeupListener {
    pool: sqlx::PgPool,
    listener: PgListener,
}

async fn subscribe(pool: &sqlx::PgPool) -> Result<PgListener, sqlx::Error> {
    let mut listener = PgListener::connect_with(pool).await?;
    listener
        .listen_all([JOBS_QUEUED, JOB_EVENTS, JOB_CANCELS])
        .await?;
    Ok(listener)
}

impl Database {
    /// Listens for other processes' wake-ups; `None` on SQLite, which has no such channel.
    pub async fn listen_for_wakeups(&self) -> Option<Result<WakeupListener, StoreError>> {
        let pool = self.postgres_pool()?.clone();
        Some(match subscribe(&pool).await {
            Ok(listener) => Ok(WakeupListener { pool, listener }),
            Err(error) => Err(error.into()),
        })
    }
}

impl WakeupListener {
    /// The next wake-up. While the database is unreachable this keeps trying to subscribe
    /// again (once a second) and reports [`Wakeup::Missed`] once it has.
    pub async fn recv(&mut self) -> Wakeup {
        match self.listener.try_recv().await {
            Ok(Some(notification)) => match notification.channel() {
                JOB_EVENTS => Wakeup::JobEvent(notification.payload().to_string()),
                JOB_CANCELS => Wakeup::JobCancel(notification.payload().to_string()),
                _ => Wakeup::JobQueued,
            },
            // The connection dropped and the listener has already reconnected and listens.
            Ok(None) => Wakeup::Missed,
            Err(error) => {
                tracing::warn!(%error, "database wake-ups lost; subscribing again");
                loop {
                    tokio::time::sleep(Duration::from_secs(1)).await;
                    if let Ok(listener) = subscribe(&self.pool).await {
                        self.listener = listener;
                        return Wakeup::Missed;
                    }
                }
            }
        }
    }
}
