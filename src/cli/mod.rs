//! Local commands over the library: training, rendering and benchmarking a dataset directory;
//! querying, exporting and evaluating the scenes a local service trained.

pub mod bench;
pub mod eval;
pub mod export;
pub mod interrupt;
pub mod local;
pub mod models;
pub mod query;
pub mod render;
pub mod train;

use std::path::Path;

use anyhow::Context;
use segsplat_gpu::{GpuContext, KernelChoices};
use segsplat_scene::{LoadOptions, Scene, load_scene};

/// Loads a dataset directory (any supported format).
pub fn open_scene(dir: &Path) -> anyhow::Result<Scene> {
    load_scene(dir, &LoadOptions::default())
        .with_context(|| format!("cannot load the dataset in {}", dir.display()))
}

/// The best GPU adapter (hardware first, software Vulkan otherwise).
pub fn open_gpu() -> anyhow::Result<GpuContext> {
    let ctx = GpuContext::new_default()
        .context("no usable GPU adapter")?
        .with_kernel_choices(kernel_choices_from_env()?);
    tracing::info!(
        adapter = %ctx.report.name,
        backend = %ctx.report.backend,
        float_atomics = ctx.report.float32_atomics,
        "GPU ready"
    );
    Ok(ctx)
}

/// Kernel variants forced by `SEGSPLAT_RASTER_KERNEL` (`pixels` / `columns`) and
/// `SEGSPLAT_GEMM_KERNEL` (`tiled` / `rows`), for comparing variants on one machine
/// (docs/benchmarks.md). A value that names no variant is an error, not a silent default.
fn kernel_choices_from_env() -> anyhow::Result<KernelChoices> {
    fn forced<T: std::str::FromStr>(variable: &str) -> anyhow::Result<Option<T>>
    where
        T::Err: std::error::Error + Send + Sync + 'static,
    {
        match std::env::var(variable) {
            Ok(value) => Ok(Some(value.parse().with_context(|| variable.to_string())?)),
            Err(std::env::VarError::NotPresent) => Ok(None),
            Err(error) => Err(error).with_context(|| variable.to_string()),
        }
    }
    Ok(KernelChoices {
        raster: forced("SEGSPLAT_RASTER_KERNEL")?,
        gemm: forced("SEGSPLAT_GEMM_KERNEL")?,
    })
}

/// Peak resident memory of this process in MiB (Linux `VmHWM`); on software adapters this
/// includes "GPU" memory.
pub fn peak_resident_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|line| line.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}
