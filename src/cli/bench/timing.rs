//! The timed training loops of `bench`, and the host's side of a step (dispatches, read-backs,
//! waits, submissions) per step.

use segsplat_engine::train::Trainer;
use segsplat_gpu::{GpuContext, HostCostReading};
use serde::Serialize;

/// Steps of one trainer between turns when two are timed together.
const INTERLEAVED_STEPS: u32 = 25;

/// One trainer's timed training loop.
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct TimedRun {
    pub(super) steps: u32,
    pub(super) seconds: f64,
    /// Kernel dispatches per step, the partial-mask filter's left out.
    pub(super) dispatches_per_step: f64,
    /// What the host waited for and read back over the run.
    pub(super) host: HostCostReading,
}

impl TimedRun {
    pub(super) fn steps_per_sec(&self) -> f64 {
        f64::from(self.steps) / self.seconds.max(f64::MIN_POSITIVE)
    }

    /// Trains `trainer` to `last_step`, adding the turn's time, steps and host costs to this
    /// run; returns the kernel dispatches it recorded, the partial-mask filter's left out.
    pub(super) fn train_turn(
        &mut self,
        ctx: &GpuContext,
        trainer: &mut Trainer,
        last_step: u32,
    ) -> anyhow::Result<u64> {
        let first_step = trainer.step();
        let before = segsplat_gpu::dispatches_on_this_thread();
        let filter_before = trainer.partial_filter_cost().dispatches;
        let host_before = ctx.host_costs.reading_on_this_thread();
        let started = std::time::Instant::now();
        // Ends on a read-back, so the turn's GPU work is done when the clock stops.
        let progress = trainer.run_until(last_step, |_| true)?;
        self.seconds += started.elapsed().as_secs_f64();
        self.host
            .add(&ctx.host_costs.reading_on_this_thread().since(&host_before));
        self.steps += progress.step - first_step;
        let filter = trainer.partial_filter_cost().dispatches - filter_before;
        Ok(segsplat_gpu::dispatches_on_this_thread() - before - filter)
    }

    /// The host's side of a step, per step.
    pub(super) fn host_report(&self) -> HostCostReport {
        let steps = f64::from(self.steps.max(1));
        let waited = self.host.wait_seconds().min(self.seconds);
        let submitted = self.host.submit_seconds().min(self.seconds - waited);
        HostCostReport {
            bytes_read_back_per_step: self.host.bytes_read_back as f64 / steps,
            read_backs_per_step: self.host.read_backs as f64 / steps,
            host_ms_per_step: (self.seconds - waited - submitted) * 1e3 / steps,
            wait_ms_per_step: waited * 1e3 / steps,
            submit_ms_per_step: submitted * 1e3 / steps,
            finish_ms_per_step: self.host.finish_seconds() * 1e3 / steps,
            bind_groups_created_per_step: self.host.bind_groups_created as f64 / steps,
            buffers_created_per_step: self.host.buffers_created as f64 / steps,
            compute_passes_per_step: self.host.compute_passes as f64 / steps,
        }
    }
}

/// Per training step: what the host read back, and its time outside the device's work
/// (encoding, progress, densification on the CPU), waiting for the device, and inside queue
/// submissions. A GPU's queue returns from a submission at once and the waits hold its
/// arithmetic; lavapipe's queue runs the work inside the submission, so there the submit
/// milliseconds hold it. Either way `host_ms_per_step` is the host's own share.
#[derive(Debug, Clone, Copy, Serialize)]
pub(super) struct HostCostReport {
    bytes_read_back_per_step: f64,
    read_backs_per_step: f64,
    host_ms_per_step: f64,
    wait_ms_per_step: f64,
    submit_ms_per_step: f64,
    /// Of `host_ms_per_step`, the time in wgpu's `finish` of the step's encoders, where wgpu 30
    /// checks the recorded commands, works out their barriers and records the backend's
    /// commands (on Vulkan the driver's `vkCmd*`): what is left of the host's share is
    /// segsplat's own recording and wgpu's argument capture.
    finish_ms_per_step: f64,
    /// Bind groups made a step (the rest come from the cache; see docs/engine.md).
    bind_groups_created_per_step: f64,
    /// Buffers made a step for kernel parameters or slot tables (0 in a steady step).
    buffers_created_per_step: f64,
    /// Compute passes recorded a step: consecutive dispatches share one (`segsplat_gpu::Encoder`),
    /// so this is far below `dispatches_per_step`.
    compute_passes_per_step: f64,
}

/// Trains each of `trainers` to its last step, timing each. With more than one they take turns
/// of [`INTERLEAVED_STEPS`] steps, each turn waited for to its end, so a change in the machine's
/// speed (other processes, a shared host) falls on every trainer alike instead of on whichever
/// ran in those seconds: the step-time ratio of `--object-loss` comes from this.
pub(super) fn timed_runs(
    ctx: &GpuContext,
    trainers: &mut [&mut Trainer],
) -> anyhow::Result<Vec<TimedRun>> {
    let turn = if trainers.len() > 1 {
        INTERLEAVED_STEPS
    } else {
        u32::MAX
    };
    let mut runs = vec![TimedRun::default(); trainers.len()];
    let mut dispatches = vec![0u64; trainers.len()];
    while trainers
        .iter()
        .any(|trainer| trainer.step() < trainer.end_step())
    {
        for ((trainer, run), dispatched) in trainers.iter_mut().zip(&mut runs).zip(&mut dispatches)
        {
            let first_step = trainer.step();
            if first_step >= trainer.end_step() {
                continue;
            }
            *dispatched += run.train_turn(ctx, trainer, first_step.saturating_add(turn))?;
        }
    }
    for (run, dispatched) in runs.iter_mut().zip(dispatches) {
        run.dispatches_per_step = dispatched as f64 / f64::from(run.steps.max(1));
    }
    Ok(runs)
}
