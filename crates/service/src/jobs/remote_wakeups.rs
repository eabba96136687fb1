//! Carries other processes' wake-ups (PostgreSQL LISTEN/NOTIFY, `store::wakeups`) into this
//! process's own: a job queued anywhere wakes this process's idle workers, and a job event
//! written anywhere wakes this process's event followers (SSE, `follow_job_events`).

use std::sync::Arc;

use tokio::sync::Notify;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use super::JobEventBus;
use crate::store::Database;
use crate::store::wakeups::Wakeup;

/// Starts forwarding until `stop`; `None` on SQLite, whose processes poll instead.
pub async fn forward_remote_wakeups(
    database: &Database,
    bus: JobEventBus,
    job_queued: Arc<Notify>,
    stop: CancellationToken,
) -> Option<JoinHandle<()>> {
    let mut listener = match database.listen_for_wakeups().await? {
        Ok(listener) => listener,
        Err(error) => {
            tracing::warn!(%error, "cannot listen for other processes' wake-ups; polling only");
            return None;
        }
    };
    Some(tokio::spawn(async move {
        loop {
            let wakeup = tokio::select! {
                wakeup = listener.recv() => wakeup,
                () = stop.cancelled() => return,
            };
            match wakeup {
                Wakeup::JobQueued => job_queued.notify_waiters(),
                Wakeup::JobEvent(job_id) => bus.notify(&job_id),
                Wakeup::JobCancel(job_id) => bus.notify_cancel(&job_id),
                Wakeup::Missed => {
                    job_queued.notify_waiters();
                    bus.notify_all();
                }
            }
        }
    }))
}
