//! GPU timing from timestamp queries, for benchmarks (`segsplat bench --profile-kernels`) and a
//! job's `gpu_busy_fraction`. Two kinds of profile:
//!
//! - **kernels** ([`KernelProfiler::start`]): every [`Kernel`](super::Kernel) dispatch gets a
//!   pass of its own with a timestamp at its start and end, so the time is told by kernel.
//!   Wall-clock timing around a submission cannot say which of a step's ~100 dispatches the
//!   time went to; these timestamps can. The extra passes cost the host, and the sum leaves out
//!   what the GPU spends between dispatches (barriers, launches).
//! - **passes** ([`KernelProfiler::start_passes`]): the shared passes of [`crate::Encoder`]
//!   get the timestamps, so the work is recorded as it is untimed, and the GPU's timeline shows
//!   how much of it the passes fill ([`PassTimeline`]): what a step costs the GPU including
//!   the gaps between its dispatches, and whether the host kept the GPU fed.
//!
//! No extra submissions or waits either way. Off by default, and idle outside a profile.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::thread::ThreadId;

use serde::Serialize;

use super::context::{GpuContext, GpuError};
use super::pass_timeline::PassTimeline;

/// Passes timed in one profile; later passes run untimed (counted in `untimed_passes`).
const PASS_CAPACITY: u32 = 2048;

/// Time spent in one kernel (all passes with its label) since the last take.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct KernelTime {
    pub kernel: String,
    pub passes: u32,
    pub ms: f64,
}

/// What [`KernelProfiler::take`] returns: kernels by time spent, most first.
#[derive(Debug, Clone, Serialize, Default)]
pub struct KernelProfile {
    pub kernels: Vec<KernelTime>,
    pub total_ms: f64,
    pub untimed_passes: u32,
}

/// What an active profile times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
enum Timing {
    #[default]
    Off,
    /// Each dispatch in a pass of its own.
    Kernels,
    /// The encoders' shared passes as they are.
    Passes,
}

/// The label of a shared pass's timestamps.
const SHARED_PASS: &str = "shared pass";

#[derive(Debug, Default)]
struct Recorded {
    timing: Timing,
    /// The thread whose passes the profile times: a context may be shared (two job slots on
    /// one GPU), and another thread's passes could still be unrecorded or unsubmitted when the
    /// owner reads the timestamps back.
    owner: Option<ThreadId>,
    labels: Vec<&'static str>,
    untimed: u32,
}

/// Timestamp queries for every profiled pass, with each pass's kernel label.
#[derive(Debug)]
pub struct KernelProfiler {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    recorded: Mutex<Recorded>,
    /// Held through a [`measure_busy`], so two callers sharing the context do not take turns
    /// resetting each other's profile.
    sampling: Mutex<()>,
}

impl KernelProfiler {
    /// Fails when the adapter has no timestamp queries.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        if !ctx.features.contains(wgpu::Features::TIMESTAMP_QUERY) {
            return Err(GpuError::Device(format!(
                "{} has no timestamp queries, so kernels cannot be profiled",
                ctx.report.name
            )));
        }
        let queries = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("kernel profiler"),
            ty: wgpu::QueryType::Timestamp,
            count: PASS_CAPACITY * 2,
        });
        let resolved = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kernel profiler resolve"),
            size: u64::from(PASS_CAPACITY) * 2 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Ok(Self {
            queries,
            resolved,
            recorded: Mutex::new(Recorded::default()),
            sampling: Mutex::new(()),
        })
    }

    fn recorded(&self) -> std::sync::MutexGuard<'_, Recorded> {
        self.recorded
            .lock()
            .unwrap_or_else(|poison| poison.into_inner())
    }

    /// Starts timing each dispatch this thread records from now on (until
    /// [`KernelProfiler::take`]); `false`, and nothing changes, while another thread's profile
    /// runs.
    pub fn start(&self) -> bool {
        self.start_timing(Timing::Kernels)
    }

    /// Starts timing the encoders' shared passes this thread opens from now on (until
    /// [`KernelProfiler::take_timeline`]); `false` while another thread's profile runs.
    pub fn start_passes(&self) -> bool {
        self.start_timing(Timing::Passes)
    }

    fn start_timing(&self, timing: Timing) -> bool {
        let me = crate::uniform_ring::this_thread();
        let mut recorded = self.recorded();
        if recorded.timing != Timing::Off && recorded.owner != Some(me) {
            return false;
        }
        *recorded = Recorded {
            timing,
            owner: Some(me),
            ..Recorded::default()
        };
        true
    }

    /// The timestamp writes for the next pass of kernel `label`, a dispatch's own; `None`
    /// outside a kernels profile or once the query set is full.
    pub fn pass_writes(&self, label: &'static str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        self.writes(Timing::Kernels, label)
    }

    /// The timestamp writes for the next shared pass of an encoder; `None` outside a passes
    /// profile or once the query set is full.
    pub fn shared_pass_writes(&self) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        self.writes(Timing::Passes, SHARED_PASS)
    }

    fn writes(
        &self,
        timing: Timing,
        label: &'static str,
    ) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let mut recorded = self.recorded();
        if recorded.timing != timing || recorded.owner != Some(crate::uniform_ring::this_thread()) {
            return None;
        }
        let pass = recorded.labels.len() as u32;
        if pass >= PASS_CAPACITY {
            recorded.untimed += 1;
            return None;
        }
        recorded.labels.push(label);
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(pass * 2),
            end_of_pass_write_index: Some(pass * 2 + 1),
        })
    }

    /// Per-kernel times of the passes recorded since [`KernelProfiler::start`], which must all
    /// have been submitted. Waits for the GPU and ends the profile.
    pub fn take(&self, ctx: &GpuContext) -> Result<KernelProfile, GpuError> {
        let (recorded, ticks) = self.take_ticks(ctx)?;
        if recorded.labels.is_empty() {
            return Ok(KernelProfile {
                untimed_passes: recorded.untimed,
                ..KernelProfile::default()
            });
        }
        Ok(profile_from_ticks(
            &recorded.labels,
            &ticks,
            f64::from(ctx.queue.get_timestamp_period()),
            recorded.untimed,
        ))
    }

    /// The GPU's timeline of the shared passes recorded since [`KernelProfiler::start_passes`],
    /// which must all have been submitted. Waits for the GPU and ends the profile.
    pub fn take_timeline(&self, ctx: &GpuContext) -> Result<PassTimeline, GpuError> {
        let (recorded, ticks) = self.take_ticks(ctx)?;
        Ok(PassTimeline::from_ticks(
            &ticks,
            f64::from(ctx.queue.get_timestamp_period()),
            recorded.untimed,
        ))
    }

    /// Ends the profile and reads its timestamps back (a begin and an end per pass); another
    /// thread's profile is left running, and this caller gets none.
    fn take_ticks(&self, ctx: &GpuContext) -> Result<(Recorded, Vec<u64>), GpuError> {
        let recorded = {
            let mut recorded = self.recorded();
            if recorded
                .owner
                .is_some_and(|owner| owner != crate::uniform_ring::this_thread())
            {
                return Ok((Recorded::default(), Vec::new()));
            }
            std::mem::take(&mut *recorded)
        };
        let passes = recorded.labels.len() as u32;
        if passes == 0 {
            return Ok((recorded, Vec::new()));
        }
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("kernel profiler resolve"),
            });
        encoder.resolve_query_set(&self.queries, 0..passes * 2, &self.resolved, 0);
        ctx.submit_untimed(encoder.finish());
        let ticks: Vec<u64> =
            bytemuck::pod_collect_to_vec(&ctx.read_buffer(&self.resolved, u64::from(passes) * 16)?);
        Ok((recorded, ticks))
    }
}

/// What [`measure_busy`] found: the work run with its shared passes timed, then run again with
/// each dispatch timed.
#[derive(Debug, Clone)]
pub struct BusyReading {
    /// Wall milliseconds of the first run, from an idle device to an idle device (so with the
    /// host's latency before the GPU gets its first pass, which the timeline leaves out).
    pub wall_ms: f64,
    /// The GPU's timeline over the first run: how full its passes kept the GPU.
    pub timeline: PassTimeline,
    /// Wall milliseconds of the second run: longer, as each timed dispatch has a pass of its own.
    pub profiled_wall_ms: f64,
    /// GPU time of the second run, by kernel.
    pub profile: KernelProfile,
}

impl BusyReading {
    /// The share of the GPU's timeline over the first run that its passes filled
    /// ([`PassTimeline::busy_fraction`]).
    pub fn busy_fraction(&self) -> f64 {
        self.timeline.busy_fraction()
    }

    /// The reading per unit of work, given the units of each run (what a report carries).
    pub fn summary(&self, timeline_units: u32, kernel_units: u32) -> BusySummary {
        let per_timeline_unit = |value: f64| value / f64::from(timeline_units.max(1));
        let kernel_ms = self.profile.total_ms / f64::from(kernel_units.max(1));
        let pass_ms = per_timeline_unit(self.timeline.busy_ms);
        BusySummary {
            gpu_busy_fraction: self.busy_fraction(),
            timeline_steps: timeline_units,
            passes_per_step: per_timeline_unit(f64::from(self.timeline.passes)),
            pass_ms_per_step: pass_ms,
            idle_ms_per_step: per_timeline_unit(self.timeline.idle_ms()),
            longest_gap_ms: self.timeline.longest_gap_ms,
            wall_ms_per_step: per_timeline_unit(self.wall_ms),
            kernel_steps: kernel_units,
            kernel_ms_per_step: kernel_ms,
            between_dispatches_ms_per_step: (pass_ms - kernel_ms).max(0.0),
        }
    }
}

/// A [`BusyReading`] per step of training (the unit of work `bench` and a job measure), as
/// `bench --profile-kernels` and a job's `metrics.json` report it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct BusySummary {
    /// The share of the GPU's timeline its passes filled, over `timeline_steps` steps.
    pub gpu_busy_fraction: f64,
    pub timeline_steps: u32,
    pub passes_per_step: f64,
    /// GPU milliseconds a step inside the step's passes (its kernels and what the GPU does
    /// between them: barriers, launches).
    pub pass_ms_per_step: f64,
    /// GPU milliseconds a step with no pass running: where the host did not keep up, plus the
    /// untimed copies and clears between passes.
    pub idle_ms_per_step: f64,
    /// The longest such stretch in the sample.
    pub longest_gap_ms: f64,
    /// Wall milliseconds a step of the timeline's run, from an idle device to an idle device.
    pub wall_ms_per_step: f64,
    /// Steps run with each dispatch timed.
    pub kernel_steps: u32,
    /// GPU milliseconds a step inside the kernels themselves (each dispatch timed alone).
    pub kernel_ms_per_step: f64,
    /// `pass_ms_per_step - kernel_ms_per_step`: what a step's passes cost the GPU beyond their
    /// kernels (from two samples, so only roughly).
    pub between_dispatches_ms_per_step: f64,
}

/// Runs `run(timeline_units)` with the encoders' shared passes timed, for how full the host keeps
/// the GPU ([`PassTimeline`]), then `run(kernel_units)` with every dispatch timed, for the GPU's
/// time by kernel. `run(n)` must record `n` units of the same work (training steps). The
/// timeline's run can be long (it times a few passes a step); the kernels' run holds at most
/// the profiler's 2048 dispatches. Only passes this thread records are timed, so on a context
/// shared with other threads the timeline is this caller's work alone, and the GPU's time on
/// theirs reads as idle. `None` without a profiler, while another thread measures, or when
/// either run recorded more passes than the profiler holds.
pub fn measure_busy<E>(
    ctx: &GpuContext,
    timeline_units: u32,
    kernel_units: u32,
    mut run: impl FnMut(u32) -> Result<(), E>,
    gpu_error: impl Fn(GpuError) -> E,
) -> Result<Option<BusyReading>, E> {
    let Some(profiler) = ctx.profiler.as_ref() else {
        return Ok(None);
    };
    let _sampling = match profiler.sampling.try_lock() {
        Ok(guard) => guard,
        // A measure that panicked left nothing to protect.
        Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
        Err(std::sync::TryLockError::WouldBlock) => return Ok(None),
    };
    ctx.wait_idle().map_err(&gpu_error)?;
    if !profiler.start_passes() {
        return Ok(None);
    }
    let started = std::time::Instant::now();
    let ran = run(timeline_units);
    // Taken even when the run failed, so the profiler is left idle.
    let timeline = profiler.take_timeline(ctx).map_err(&gpu_error)?;
    ran?;
    let wall_ms = started.elapsed().as_secs_f64() * 1e3;
    if !profiler.start() {
        return Ok(None);
    }
    let started = std::time::Instant::now();
    let ran = run(kernel_units);
    let profile = profiler.take(ctx).map_err(&gpu_error)?;
    ran?;
    let profiled_wall_ms = started.elapsed().as_secs_f64() * 1e3;
    if profile.untimed_passes != 0 || timeline.untimed_passes != 0 || timeline.passes == 0 {
        return Ok(None);
    }
    Ok(Some(BusyReading {
        wall_ms,
        timeline,
        profiled_wall_ms,
        profile,
    }))
}

/// Sums each label's pass durations (`ticks` holds a begin and an end per pass).
fn profile_from_ticks(
    labels: &[&'static str],
    ticks: &[u64],
    ns_per_tick: f64,
    untimed_passes: u32,
) -> KernelProfile {
    let mut by_kernel: BTreeMap<&str, (u32, f64)> = BTreeMap::new();
    for (label, pair) in labels.iter().zip(ticks.chunks_exact(2)) {
        let ms = pair[1].saturating_sub(pair[0]) as f64 * ns_per_tick * 1e-6;
        let entry = by_kernel.entry(label).or_default();
        entry.0 += 1;
        entry.1 += ms;
    }
    let mut kernels: Vec<KernelTime> = by_kernel
        .into_iter()
        .map(|(kernel, (passes, ms))| KernelTime {
            kernel: kernel.to_string(),
            passes,
            ms,
        })
        .collect();
    kernels.sort_by(|a, b| b.ms.total_cmp(&a.ms));
    let total_ms = kernels.iter().map(|k| k.ms).sum();
    KernelProfile {
        kernels,
        total_ms,
        untimed_passes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_are_summed_per_kernel_and_sorted_by_time() {
        let labels = ["sort", "raster", "sort"];
        let ticks = [0, 10, 10, 110, 200, 230];
        let profile = profile_from_ticks(&labels, &ticks, 1e6, 3);
        assert_eq!(profile.kernels.len(), 2);
        assert_eq!(profile.kernels[0].kernel, "raster");
        assert_eq!(profile.kernels[0].passes, 1);
        assert!((profile.kernels[0].ms - 100.0).abs() < 1e-9);
        assert_eq!(profile.kernels[1].passes, 2);
        assert!((profile.kernels[1].ms - 40.0).abs() < 1e-9);
        assert!((profile.total_ms - 140.0).abs() < 1e-9);
        assert_eq!(profile.untimed_passes, 3);
    }
}
