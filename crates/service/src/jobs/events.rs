//! Wake-ups for Server-Sent-Events subscribers: which job just got a new event. The events
//! themselves are read from the database, so a lagging subscriber loses nothing and events from
//! worker processes elsewhere still arrive (subscribers also poll).

use tokio::sync::broadcast;

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

    pub fn subscribe(&self) -> broadcast::Receiver<String> {
        self.sender.subscribe()
    }
}
