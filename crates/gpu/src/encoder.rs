//! Commands for one submission, with consecutive dispatches recorded into one compute pass.
//!
//! A training step records about a hundred small dispatches. With a pass of its own for each,
//! the host's cost of opening, closing and validating passes is most of a step on a fast GPU
//! (the H200 spent 2.6 ms a step on the host against 2.5 ms of kernels). Inside one pass wgpu
//! still orders the dispatches: each is its own usage scope, and a buffer written by one and
//! used by the next gets its barrier, exactly as between passes.
//!
//! [`Encoder`] keeps a pass open across [`crate::Kernel::dispatch`] calls and ends it as soon as
//! anything else is recorded: every other command goes through `DerefMut` to the
//! [`wgpu::CommandEncoder`], which first ends the open pass. So callers use it where they used
//! the encoder, and copies, clears and query resolves land between the passes, in order.

use std::ops::{Deref, DerefMut};
use std::sync::Arc;

use crate::GpuContext;
use crate::host_costs::{Cost, HostCosts};
use crate::profiler::KernelProfiler;

/// A command encoder whose compute dispatches share a pass (see the module docs).
pub struct Encoder {
    /// Declared before `inner`, so a dropped encoder ends its pass before the encoder itself.
    pass: Option<wgpu::ComputePass<'static>>,
    inner: wgpu::CommandEncoder,
    host_costs: Arc<HostCosts>,
    /// Times the shared passes during a passes profile ([`KernelProfiler::start_passes`]).
    profiler: Option<Arc<KernelProfiler>>,
}

impl Encoder {
    pub fn new(ctx: &GpuContext, label: &str) -> Self {
        Self {
            pass: None,
            inner: ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) }),
            host_costs: Arc::clone(&ctx.host_costs),
            profiler: ctx.profiler.clone(),
        }
    }

    /// The open compute pass, opened here when there is none.
    pub(crate) fn shared_pass(&mut self) -> &mut wgpu::ComputePass<'static> {
        let Self {
            pass,
            inner,
            host_costs,
            profiler,
        } = self;
        pass.get_or_insert_with(|| {
            host_costs.add(Cost::ComputePasses, 1);
            inner
                .begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("dispatches"),
                    timestamp_writes: profiler
                        .as_ref()
                        .and_then(|profiler| profiler.shared_pass_writes()),
                })
                .forget_lifetime()
        })
    }

    /// A pass for one dispatch that writes timestamps around itself (the kernel profiler):
    /// the shared pass ends first, so the timestamps hold that dispatch alone.
    pub(crate) fn timed_pass(
        &mut self,
        label: &str,
        timestamp_writes: wgpu::ComputePassTimestampWrites<'_>,
    ) -> wgpu::ComputePass<'_> {
        self.pass = None;
        self.host_costs.add(Cost::ComputePasses, 1);
        self.inner.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: Some(timestamp_writes),
        })
    }

    /// Ends the open pass, so the next dispatch opens another (what every dispatch did before
    /// passes were shared; `benches/pass_sharing.rs` compares the two).
    pub fn end_pass(&mut self) {
        self.pass = None;
    }

    /// Ends the open pass (if any) and finishes the commands for submission, timed into the
    /// context's `finish_nanos`.
    pub fn finish(mut self) -> wgpu::CommandBuffer {
        let started = std::time::Instant::now();
        self.pass = None;
        let commands = self.inner.finish();
        self.host_costs.add(
            Cost::FinishNanos,
            u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX),
        );
        commands
    }
}

impl Deref for Encoder {
    type Target = wgpu::CommandEncoder;

    fn deref(&self) -> &wgpu::CommandEncoder {
        &self.inner
    }
}

impl DerefMut for Encoder {
    /// Anything recorded on the encoder itself comes after the dispatches so far: their pass
    /// ends here (wgpu refuses commands on an encoder while one of its passes is open).
    fn deref_mut(&mut self) -> &mut wgpu::CommandEncoder {
        self.pass = None;
        &mut self.inner
    }
}

impl std::fmt::Debug for Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Encoder")
            .field("pass_open", &self.pass.is_some())
            .finish_non_exhaustive()
    }
}
