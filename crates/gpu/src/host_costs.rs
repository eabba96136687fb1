//! What the host waited for, read back and made while driving the GPU, counted per context and
//! per thread.
//!
//! On a fast GPU the host's waits and read-backs, not the kernels, bound a training step, so
//! `bench` and jobs report them per step. A context can be shared by several threads (two job
//! slots on one adapter, concurrent mask renders), and a job's figures must be its own: every
//! count goes both into the context's totals ([`HostCosts::reading`]) and into a tally of the
//! thread that made it ([`HostCosts::reading_on_this_thread`]), as do kernel dispatches
//! ([`dispatches_on_this_thread`]).

use std::cell::{Cell, RefCell};
use std::sync::atomic::{AtomicU64, Ordering};

/// One kind of count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Cost {
    BytesReadBack,
    ReadBacks,
    WaitNanos,
    SubmitNanos,
    FinishNanos,
    BindGroupsCreated,
    ComputePasses,
    BuffersCreated,
}

/// Counters of what the host waited for and read back (see [`crate::GpuContext::host_costs`]).
#[derive(Debug, Default)]
pub struct HostCosts {
    bytes_read_back: AtomicU64,
    read_backs: AtomicU64,
    wait_nanos: AtomicU64,
    submit_nanos: AtomicU64,
    finish_nanos: AtomicU64,
    bind_groups_created: AtomicU64,
    compute_passes: AtomicU64,
    buffers_created: AtomicU64,
}

thread_local! {
    /// This thread's counts, by the address of the [`HostCosts`] they were made on (a handful of
    /// contexts at most; a context dropped and another made at its address continues its
    /// tally, which readings taken as differences do not notice).
    static THREAD_TALLY: RefCell<Vec<(usize, HostCostReading)>> =
        const { RefCell::new(Vec::new()) };
    static THREAD_DISPATCHES: Cell<u64> = const { Cell::new(0) };
}

impl HostCosts {
    fn counter(&self, cost: Cost) -> &AtomicU64 {
        match cost {
            Cost::BytesReadBack => &self.bytes_read_back,
            Cost::ReadBacks => &self.read_backs,
            Cost::WaitNanos => &self.wait_nanos,
            Cost::SubmitNanos => &self.submit_nanos,
            Cost::FinishNanos => &self.finish_nanos,
            Cost::BindGroupsCreated => &self.bind_groups_created,
            Cost::ComputePasses => &self.compute_passes,
            Cost::BuffersCreated => &self.buffers_created,
        }
    }

    fn key(&self) -> usize {
        std::ptr::from_ref(self) as usize
    }

    /// Counts `amount` of `cost`, in the context's totals and in this thread's tally.
    pub(crate) fn add(&self, cost: Cost, amount: u64) {
        self.counter(cost).fetch_add(amount, Ordering::Relaxed);
        let key = self.key();
        // A thread in its own teardown has no tally left: the totals still count.
        let _ = THREAD_TALLY.try_with(|tally| {
            let mut tally = tally.borrow_mut();
            let index = match tally.iter().position(|(known, _)| *known == key) {
                Some(index) => index,
                None => {
                    tally.push((key, HostCostReading::default()));
                    tally.len() - 1
                }
            };
            tally[index].1.add_cost(cost, amount);
        });
    }

    /// Every thread's counts on this context so far.
    pub fn reading(&self) -> HostCostReading {
        HostCostReading {
            bytes_read_back: self.bytes_read_back.load(Ordering::Relaxed),
            read_backs: self.read_backs.load(Ordering::Relaxed),
            wait_nanos: self.wait_nanos.load(Ordering::Relaxed),
            submit_nanos: self.submit_nanos.load(Ordering::Relaxed),
            finish_nanos: self.finish_nanos.load(Ordering::Relaxed),
            bind_groups_created: self.bind_groups_created.load(Ordering::Relaxed),
            compute_passes: self.compute_passes.load(Ordering::Relaxed),
            buffers_created: self.buffers_created.load(Ordering::Relaxed),
        }
    }

    /// The calling thread's counts on this context so far: what a job reports as its own when
    /// other threads share the context.
    pub fn reading_on_this_thread(&self) -> HostCostReading {
        let key = self.key();
        THREAD_TALLY
            .try_with(|tally| {
                tally
                    .borrow()
                    .iter()
                    .find(|(known, _)| *known == key)
                    .map(|(_, reading)| *reading)
                    .unwrap_or_default()
            })
            .unwrap_or_default()
    }
}

/// Counts a kernel dispatch recorded on this thread: for small scenes a step costs dispatch
/// overhead more than arithmetic, so `bench` and jobs report the count a step.
pub(crate) fn count_dispatch_on_this_thread() {
    let _ = THREAD_DISPATCHES.try_with(|count| count.set(count.get() + 1));
}

/// Kernel dispatches this thread has recorded, on any context.
pub fn dispatches_on_this_thread() -> u64 {
    THREAD_DISPATCHES.try_with(Cell::get).unwrap_or(0)
}

/// A reading of [`HostCosts`]; differences of two readings give what happened in between.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct HostCostReading {
    pub bytes_read_back: u64,
    pub read_backs: u64,
    /// Time the host spent blocked on the device (waits and mapped read-backs).
    pub wait_nanos: u64,
    /// Time inside [`crate::GpuContext::submit`]: microseconds on a GPU; on a software
    /// adapter, whose queue may run the work before it returns, it holds the arithmetic.
    pub submit_nanos: u64,
    /// Time inside [`crate::Encoder::finish`], part of the host's own time: in wgpu 30 a pass's
    /// commands are checked, their barriers worked out and the backend's commands recorded
    /// (Vulkan's `vkCmd*` calls) when the encoder finishes, not when each is called.
    pub finish_nanos: u64,
    /// Bind groups created by kernels (not found in the cache).
    pub bind_groups_created: u64,
    /// Compute passes recorded (see [`crate::Encoder`]: consecutive dispatches share one).
    pub compute_passes: u64,
    /// Buffers created for kernel parameters the uniform ring could not take, and by callers
    /// that count theirs through [`crate::GpuContext::count_buffer_created`].
    pub buffers_created: u64,
}

impl HostCostReading {
    /// What happened between `earlier` and this reading.
    pub fn since(&self, earlier: &HostCostReading) -> HostCostReading {
        HostCostReading {
            bytes_read_back: self.bytes_read_back.saturating_sub(earlier.bytes_read_back),
            read_backs: self.read_backs.saturating_sub(earlier.read_backs),
            wait_nanos: self.wait_nanos.saturating_sub(earlier.wait_nanos),
            submit_nanos: self.submit_nanos.saturating_sub(earlier.submit_nanos),
            finish_nanos: self.finish_nanos.saturating_sub(earlier.finish_nanos),
            bind_groups_created: self
                .bind_groups_created
                .saturating_sub(earlier.bind_groups_created),
            compute_passes: self.compute_passes.saturating_sub(earlier.compute_passes),
            buffers_created: self.buffers_created.saturating_sub(earlier.buffers_created),
        }
    }

    fn add_cost(&mut self, cost: Cost, amount: u64) {
        let field = match cost {
            Cost::BytesReadBack => &mut self.bytes_read_back,
            Cost::ReadBacks => &mut self.read_backs,
            Cost::WaitNanos => &mut self.wait_nanos,
            Cost::SubmitNanos => &mut self.submit_nanos,
            Cost::FinishNanos => &mut self.finish_nanos,
            Cost::BindGroupsCreated => &mut self.bind_groups_created,
            Cost::ComputePasses => &mut self.compute_passes,
            Cost::BuffersCreated => &mut self.buffers_created,
        };
        *field += amount;
    }

    /// Adds `other`'s counts to these.
    pub fn add(&mut self, other: &HostCostReading) {
        self.bytes_read_back += other.bytes_read_back;
        self.read_backs += other.read_backs;
        self.wait_nanos += other.wait_nanos;
        self.submit_nanos += other.submit_nanos;
        self.finish_nanos += other.finish_nanos;
        self.bind_groups_created += other.bind_groups_created;
        self.compute_passes += other.compute_passes;
        self.buffers_created += other.buffers_created;
    }

    pub fn wait_seconds(&self) -> f64 {
        self.wait_nanos as f64 * 1e-9
    }

    pub fn submit_seconds(&self) -> f64 {
        self.submit_nanos as f64 * 1e-9
    }

    pub fn finish_seconds(&self) -> f64 {
        self.finish_nanos as f64 * 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_thread_reads_its_own_counts_and_the_context_all_of_them() {
        let costs = HostCosts::default();
        costs.add(Cost::ReadBacks, 1);
        costs.add(Cost::BytesReadBack, 100);
        std::thread::scope(|scope| {
            scope.spawn(|| {
                costs.add(Cost::ReadBacks, 2);
                costs.add(Cost::BytesReadBack, 5000);
                count_dispatch_on_this_thread();
                let theirs = costs.reading_on_this_thread();
                assert_eq!((theirs.read_backs, theirs.bytes_read_back), (2, 5000));
                assert_eq!(dispatches_on_this_thread(), 1);
            });
        });
        let mine = costs.reading_on_this_thread();
        assert_eq!((mine.read_backs, mine.bytes_read_back), (1, 100));
        assert_eq!(dispatches_on_this_thread(), 0);
        let all = costs.reading();
        assert_eq!((all.read_backs, all.bytes_read_back), (3, 5100));
        // Another context's counts are its own.
        let other = HostCosts::default();
        other.add(Cost::BuffersCreated, 1);
        assert_eq!(costs.reading_on_this_thread().buffers_created, 0);
        assert_eq!(other.reading_on_this_thread().buffers_created, 1);
    }
}
