//! Who holds a lease, so a restarted process can tell its predecessors' leases from live ones.
//!
//! Lease owners are `{instance}/{slot}`. With `workers.instance_id` set, the instance is that
//! fixed name, and a process starting under it knows every running lease with that name is a
//! leftover of its previous life. Otherwise the instance is `{host}-pid{pid}-{random}`, and any
//! process on the same host can tell that a lease's process has exited (no `/proc/{pid}`), so
//! its jobs need not wait for the lease to run out. Leases of other hosts are left to expire.

pub use crate::store::process_tag::host_name;
use crate::store::process_tag::{process_tag, tagged_by_a_stopped_local_process};

/// This process's lease-owner prefix and how it recognises leases of stopped owners.
#[derive(Debug, Clone)]
pub struct ProcessIdentity {
    /// The configured stable name, if any.
    fixed: Option<String>,
    /// This process's instance name (the part before `/slot`).
    instance: String,
}

impl ProcessIdentity {
    pub fn new(fixed: Option<String>) -> Self {
        let instance = fixed.clone().unwrap_or_else(|| {
            let random = uuid::Uuid::new_v4().simple().to_string();
            format!("{}-{}", process_tag(), &random[..8])
        });
        Self { fixed, instance }
    }

    pub fn instance(&self) -> &str {
        &self.instance
    }

    /// At start: leases of this identity's previous life, or of a stopped process on this host.
    pub fn owned_by_a_previous_life(&self, owner: &str) -> bool {
        let instance = instance_of(owner);
        if self.fixed.as_deref() == Some(instance) {
            return true;
        }
        self.owned_by_a_stopped_local_process(owner)
    }

    /// Any time: leases of a process on this host that has exited (never this process's own).
    pub fn owned_by_a_stopped_local_process(&self, owner: &str) -> bool {
        let instance = instance_of(owner);
        instance != self.instance && tagged_by_a_stopped_local_process(instance)
    }
}

fn instance_of(owner: &str) -> &str {
    owner
        .rsplit_once('/')
        .map_or(owner, |(instance, _)| instance)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recognises_stopped_owners() {
        let me = ProcessIdentity::new(None);
        let host = host_name();
        assert!(!me.owned_by_a_stopped_local_process(&format!("{}/0", me.instance())));
        // A pid that cannot exist (above the kernel's pid_max).
        let dead = format!("{host}-pid4294967-abcdef12/0");
        assert!(me.owned_by_a_stopped_local_process(&dead));
        // A live process, and another service inside this one.
        let alive = format!("{host}-pid1-abcdef12/0");
        assert!(!me.owned_by_a_stopped_local_process(&alive));
        let sibling = format!("{host}-pid{}-abcdef12/0", std::process::id());
        assert!(!me.owned_by_a_stopped_local_process(&sibling));
        assert!(!me.owned_by_a_stopped_local_process("otherhost-pid4294967-abcdef12/0"));
        assert!(!me.owned_by_a_stopped_local_process("dead-worker/0"));

        let fixed = ProcessIdentity::new(Some("gpu-box-1".to_string()));
        assert_eq!(fixed.instance(), "gpu-box-1");
        assert!(fixed.owned_by_a_previous_life("gpu-box-1/3"));
        assert!(!fixed.owned_by_a_previous_life("gpu-box-2/0"));
        assert!(!fixed.owned_by_a_stopped_local_process("gpu-box-1/3"));
    }
}
