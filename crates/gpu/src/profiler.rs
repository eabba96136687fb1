//! Per-kernel GPU timing from timestamp queries, for benchmarks (`segsplat bench --profile-kernels`).
//!
//! While a profile runs, every [`Kernel`](super::Kernel) built on a context with profiling on
//! writes a timestamp at the start and end of each of its passes. Wall-clock timing around a
//! submission cannot say which of a step's ~100 passes the time went to; these timestamps can,
//! without changing what is recorded (no extra submissions or waits). Off by default, and idle
//! outside a profile.

use std::collections::BTreeMap;
use std::sync::Mutex;

use serde::Serialize;

use super::context::{GpuContext, GpuError};

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

#[derive(Debug, Default)]
struct Recorded {
    active: bool,
    labels: Vec<&'static str>,
    untimed: u32,
}

/// Timestamp queries for every profiled pass, with each pass's kernel label.
#[derive(Debug)]
pub struct KernelProfiler {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    recorded: Mutex<Recorded>,
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
        })
    }

    fn recorded(&self) -> std::sync::MutexGuard<'_, Recorded> {
        self.recorded
            .lock()
            .unwrap_or_else(|poison| poison.into_inner())
    }

    /// Starts timing passes recorded from now on (until [`KernelProfiler::take`]).
    pub fn start(&self) {
        *self.recorded() = Recorded {
            active: true,
            ..Recorded::default()
        };
    }

    /// The timestamp writes for the next pass of kernel `label`; `None` outside a profile or once
    /// the query set is full.
    pub fn pass_writes(&self, label: &'static str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let mut recorded = self.recorded();
        if !recorded.active {
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
        let recorded = std::mem::take(&mut *self.recorded());
        let passes = recorded.labels.len() as u32;
        if passes == 0 {
            return Ok(KernelProfile {
                untimed_passes: recorded.untimed,
                ..KernelProfile::default()
            });
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
        let ns_per_tick = f64::from(ctx.queue.get_timestamp_period());
        Ok(profile_from_ticks(
            &recorded.labels,
            &ticks,
            ns_per_tick,
            recorded.untimed,
        ))
    }
}

/// What [`measure_busy`] found: the same work run untimed and then timed.
#[derive(Debug, Clone)]
pub struct BusyReading {
    /// Wall milliseconds of the untimed run, from an idle device to an idle device.
    pub wall_ms: f64,
    /// Wall milliseconds of the timed run: longer, as each timed dispatch has a pass of its own.
    pub profiled_wall_ms: f64,
    /// GPU time of the timed run, by kernel.
    pub profile: KernelProfile,
}

impl BusyReading {
    /// The share of the untimed run's wall time the GPU spent in its kernels (at most 1).
    pub fn busy_fraction(&self) -> f64 {
        (self.profile.total_ms / self.wall_ms.max(1e-9)).min(1.0)
    }
}

/// Runs `run` twice, which must record the same work each time (a fixed number of training
/// steps): first untimed, for the wall time, then with every pass timed, for the GPU time. Timing
/// gives every dispatch a pass of its own (see [`crate::Encoder`]), which costs the host more
/// than the shared pass untimed work gets, so the wall time of a timed run would understate how
/// busy the GPU is. `None` without a profiler, or when the profiler dropped passes.
pub fn measure_busy<E>(
    ctx: &GpuContext,
    mut run: impl FnMut() -> Result<(), E>,
    gpu_error: impl Fn(GpuError) -> E,
) -> Result<Option<BusyReading>, E> {
    let Some(profiler) = ctx.profiler.as_ref() else {
        return Ok(None);
    };
    ctx.wait_idle().map_err(&gpu_error)?;
    let started = std::time::Instant::now();
    run()?;
    ctx.wait_idle().map_err(&gpu_error)?;
    let wall_ms = started.elapsed().as_secs_f64() * 1e3;
    profiler.start();
    let started = std::time::Instant::now();
    let ran = run();
    // Taken even when the run failed, so the profiler is left idle.
    let profile = profiler.take(ctx).map_err(&gpu_error)?;
    ran?;
    let profiled_wall_ms = started.elapsed().as_secs_f64() * 1e3;
    if profile.untimed_passes != 0 || wall_ms <= 0.0 {
        return Ok(None);
    }
    Ok(Some(BusyReading {
        wall_ms,
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
