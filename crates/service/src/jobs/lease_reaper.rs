//! The lease reaper: re-queues (or fails) jobs whose worker stopped renewing its lease, or whose
//! worker's process on this host has exited.
//!
//! Leases run out during an outage of the database too, through no fault of their holders: no
//! heartbeat could reach it. When the database comes back, the reaper and the holders' heartbeats
//! race for it, and a reaper that wins re-queues a job whose worker is alive and stepping (it
//! then learns at its next heartbeat that it lost the lease, stops, and the job is run again from
//! its checkpoint). So after a tick that could not reach the database, the reaper gives the
//! holders one lease to renew before it reaps expired leases again ([`ReapGate`]). A worker that
//! really died is reaped one lease later than it would have been. Owners known to be gone
//! (`requeue_leases_of_gone_owners`) are reaped at once, outage or not.

use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::Notify;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::warn;

use super::{JobEventBus, ProcessIdentity};
use crate::store::Database;

/// Whether expired leases may be reaped now, given what the reaper's last ticks saw.
#[derive(Debug)]
struct ReapGate {
    /// The lease holders get this long after an outage ends to renew.
    lease: Duration,
    /// The last tick could not reach the database.
    unreachable: bool,
    /// Expired leases are left alone until then.
    grace_until: Option<Instant>,
}

impl ReapGate {
    fn new(lease: Duration) -> Self {
        Self {
            lease,
            unreachable: false,
            grace_until: None,
        }
    }

    fn may_reap_expired(&self, now: Instant) -> bool {
        !self.unreachable && self.grace_until.is_none_or(|until| now >= until)
    }

    /// A tick reached the database.
    fn reached(&mut self, now: Instant) {
        if self.unreachable {
            self.unreachable = false;
            self.grace_until = Some(now + self.lease);
        }
    }

    /// A tick could not reach the database.
    fn unreachable(&mut self) {
        self.unreachable = true;
        self.grace_until = None;
    }
}

/// Periodically re-queues (or fails) jobs whose lease expired or whose worker's process on this
/// host has exited.
pub struct LeaseReaper {
    shutdown: CancellationToken,
    task: JoinHandle<()>,
}

impl LeaseReaper {
    /// Reaps every `every`; `lease` is the jobs' lease (`jobs.lease_secs`), the grace the
    /// holders get after an outage of the database.
    pub fn start(
        database: Database,
        identity: ProcessIdentity,
        bus: JobEventBus,
        job_queued: Arc<Notify>,
        every: Duration,
        lease: Duration,
    ) -> Self {
        let shutdown = CancellationToken::new();
        let stop = shutdown.clone();
        let task = tokio::spawn(async move {
            let mut ticker = tokio::time::interval(every);
            let mut gate = ReapGate::new(lease);
            loop {
                tokio::select! {
                    _ = ticker.tick() => {}
                    _ = stop.cancelled() => break,
                }
                // Gone owners first: that query also tells whether the database is back.
                let gone = database
                    .requeue_leases_of_gone_owners(|owner| {
                        identity.owned_by_a_stopped_local_process(owner)
                    })
                    .await;
                let reaped = match gone {
                    Ok(mut gone) => {
                        gate.reached(Instant::now());
                        if gate.may_reap_expired(Instant::now()) {
                            database.requeue_expired_leases().await.map(|expired| {
                                gone.extend(expired);
                                gone
                            })
                        } else {
                            Ok(gone)
                        }
                    }
                    Err(error) => Err(error),
                };
                match reaped {
                    Ok(reaped) => {
                        for lease in &reaped {
                            warn!(job_id = %lease.job_id, owner = ?lease.previous_owner,
                                state = lease.new_state.as_str(), "job lease expired");
                            bus.notify(&lease.job_id);
                        }
                        if !reaped.is_empty() {
                            metrics::counter!("segsplat_job_leases_expired_total")
                                .increment(reaped.len() as u64);
                            job_queued.notify_waiters();
                        }
                    }
                    Err(error) => {
                        gate.unreachable();
                        warn!(%error, "re-queueing expired leases failed");
                    }
                }
            }
        });
        Self { shutdown, task }
    }

    pub async fn shutdown(self) {
        self.shutdown.cancel();
        let _ = self.task.await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expired_leases_wait_one_lease_after_an_outage_ends() {
        let lease = Duration::from_millis(800);
        let start = Instant::now();
        let mut gate = ReapGate::new(lease);
        assert!(gate.may_reap_expired(start), "no outage seen: reaps");
        gate.reached(start);
        assert!(gate.may_reap_expired(start), "reaching it is no outage");

        gate.unreachable();
        assert!(!gate.may_reap_expired(start), "during the outage");
        let back = start + Duration::from_secs(3);
        gate.reached(back);
        assert!(!gate.may_reap_expired(back), "the holders' turn to renew");
        assert!(!gate.may_reap_expired(back + lease / 2));
        gate.reached(back + lease / 2);
        assert!(
            !gate.may_reap_expired(back + lease / 2),
            "a second good tick does not shorten the grace"
        );
        assert!(gate.may_reap_expired(back + lease), "one lease later");

        // A second outage during the grace starts it again when it ends.
        gate.unreachable();
        gate.reached(back + lease * 2);
        assert!(!gate.may_reap_expired(back + lease * 2));
        assert!(gate.may_reap_expired(back + lease * 3));
    }
}
