//! `bench --profile-kernels`: GPU time by kernel and how full the host keeps the GPU's timeline.

use anyhow::Context;
use segsplat_engine::train::Trainer;
use segsplat_gpu::GpuContext;
use segsplat_gpu::profiler::KernelTime;
use serde::Serialize;

/// `--profile-kernels`: GPU time per training step by kernel, averaged over `steps`, and how
/// full the host kept the GPU over `--busy-steps` steps before them.
#[derive(Serialize)]
pub(super) struct KernelProfileReport {
    steps: u32,
    /// GPU milliseconds a step inside the kernels (each dispatch timed in a pass of its own).
    gpu_ms_per_step: f64,
    /// Wall time per step of the timeline's steps, from an idle device to an idle device.
    wall_ms_per_step: f64,
    /// Wall time per step of the kernel-timed steps: each timed dispatch has a pass of its own,
    /// which costs the host more than the shared pass of untimed steps.
    profiled_wall_ms_per_step: f64,
    /// The share of the GPU's timeline the steps' passes filled (issue 38's target is at least
    /// 0.9); `timeline` has the figures behind it.
    gpu_busy_fraction: f64,
    timeline: segsplat_gpu::BusySummary,
    kernels: Vec<KernelTime>,
}

/// Runs `busy_steps` more training steps with their passes timed and `steps` more with every
/// dispatch timed (`segsplat_gpu::measure_busy`), and averages per step.
pub(super) fn profile_kernels(
    ctx: &GpuContext,
    trainer: &mut Trainer,
    steps: u32,
    busy_steps: u32,
) -> anyhow::Result<KernelProfileReport> {
    anyhow::ensure!(
        ctx.profiler.is_some(),
        "kernel profiling is not enabled on this GPU context"
    );
    let steps = steps.max(1);
    let busy_steps = busy_steps.max(1);
    let reading = segsplat_gpu::measure_busy(
        ctx,
        busy_steps,
        steps,
        |count| -> anyhow::Result<()> {
            for _ in 0..count {
                trainer.train_step()?;
            }
            Ok(())
        },
        anyhow::Error::from,
    )?
    .context(
        "more passes than the profiler holds: use fewer --profile-kernels or --busy-steps steps",
    )?;
    let timeline = reading.summary(busy_steps, steps);
    let per_step = |ms: f64| ms / f64::from(steps);
    Ok(KernelProfileReport {
        steps,
        gpu_ms_per_step: timeline.kernel_ms_per_step,
        wall_ms_per_step: timeline.wall_ms_per_step,
        profiled_wall_ms_per_step: per_step(reading.profiled_wall_ms),
        gpu_busy_fraction: timeline.gpu_busy_fraction,
        timeline,
        kernels: reading
            .profile
            .kernels
            .into_iter()
            .map(|time| KernelTime {
                ms: per_step(time.ms),
                ..time
            })
            .collect(),
    })
}
