//! Waiting out a dependency's outage inside one claim. A handler that stops because the blob
//! store cannot be reached ([`JobFailure::Unavailable`]) is not at fault: the worker keeps the
//! job's lease (its heartbeat goes on), records a `warning` job event, waits with exponential
//! backoff and runs the handler again, which resumes from its last checkpoint. No attempt is
//! spent, however long the outage; cancel and shutdown end the wait at once.

use std::time::{Duration, Instant};

use tokio_util::sync::CancellationToken;

use super::{JobFailure, ProgressReporter};

/// The first wait after an outage is seen.
const FIRST_WAIT: Duration = Duration::from_secs(1);
/// The longest wait between two runs while the outage lasts.
const LONGEST_WAIT: Duration = Duration::from_secs(30);

/// Exponential backoff from [`FIRST_WAIT`] to [`LONGEST_WAIT`].
#[derive(Debug)]
pub(crate) struct Backoff {
    next: Duration,
}

impl Backoff {
    pub(crate) fn new() -> Self {
        Self { next: FIRST_WAIT }
    }

    pub(crate) fn next_wait(&mut self) -> Duration {
        let wait = self.next;
        self.next = (self.next * 2).min(LONGEST_WAIT);
        wait
    }
}

/// Runs `run` again after every [`JobFailure::Unavailable`], waiting longer each time (back to
/// the first wait after a run that lasted longer than the longest wait: it got somewhere), and
/// returns its first other result.
pub(crate) async fn run_through_outages<F, Fut>(
    mut run: F,
    progress: &ProgressReporter,
    cancel: &CancellationToken,
    shutdown: &CancellationToken,
) -> Result<(), JobFailure>
where
    F: FnMut() -> Fut,
    Fut: Future<Output = Result<(), JobFailure>>,
{
    let mut backoff = Backoff::new();
    loop {
        let started = Instant::now();
        let reason = match run().await {
            Err(JobFailure::Unavailable(reason)) => reason,
            other => return other,
        };
        if started.elapsed() > LONGEST_WAIT {
            backoff = Backoff::new();
        }
        let wait = backoff.next_wait();
        let message = format!(
            "{reason}; running the job again in {} s from its last checkpoint \
             (an outage is not counted as an attempt)",
            wait.as_secs_f64()
        );
        tracing::warn!("{message}");
        if let Err(error) = progress.warn("outage", &message).await {
            tracing::warn!(%error, "warning event not recorded");
        }
        tokio::select! {
            _ = tokio::time::sleep(wait) => {}
            _ = cancel.cancelled() => return Err(JobFailure::Cancelled),
            _ = shutdown.cancelled() => return Err(JobFailure::Interrupted),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wait_doubles_up_to_the_longest() {
        let mut backoff = Backoff::new();
        let waits: Vec<u64> = (0..7).map(|_| backoff.next_wait().as_secs()).collect();
        assert_eq!(waits, [1, 2, 4, 8, 16, 30, 30]);
    }
}
