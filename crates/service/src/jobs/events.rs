//! Wake-ups for Server-Sent-Events subscribers: which job just got a new event. The events
//! themselves are read from the database, so a lagging subscriber loses nothing and events from
//! worker processes elsewhere still arrive (subscribers also poll).

use tokio::sync::broadcast;

/// Not a job id (ids are UUIDs): the wake-up meant for every subscriber.
const EVERY_JOB: &str = "*";
/// Marks a cancel request, `cancel:{job id}`; event followers ignore it.
const CANCEL_PREFIX: &str = "cancel:";

#[derive(Debug, Clone)]
pub struct JobEventBus {
    sender: broadcast::Sender<String>,
}

impl Default for JobEventBus {
    fn default() -> Self {
        let (sender, _) = broadcast::channel(1024);
        Self { sender }
    }
}

impl JobEventBus {
    /// Tells subscribers that `job_id` has new events.
    pub fn notify(&self, job_id: &str) {
        let _ = self.sender.send(job_id.to_string());
    }

    /// Tells every subscriber to look again (wake-ups from other processes may have been
    /// missed).
    pub fn notify_all(&self) {
        let _ = self.sender.send(EVERY_JOB.to_string());
    }

    /// Tells the worker running `job_id` that a cancel was requested, so it stops at its next
    /// step instead of at its next heartbeat.
    pub fn notify_cancel(&self, job_id: &str) {
        let _ = self.sender.send(format!("{CANCEL_PREFIX}{job_id}"));
    }

    /// Whether a received wake-up asks to cancel `job_id`.
    pub fn cancels(woken: &str, job_id: &str) -> bool {
        woken.strip_prefix(CANCEL_PREFIX) == Some(job_id) || woken == EVERY_JOB
    }

    /// Whether a received wake-up concerns `job_id`.
    pub fn concerns(woken: &str, job_id: &str) -> bool {
        woken == job_id || woken == EVERY_JOB
    }

    pub fn subscribe(&self) -> broadcast::Receiver<String> {
        self.sender.subscribe()
    }
}
