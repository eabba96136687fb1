//! Local commands over the library: training, rendering and benchmarking a dataset directory;
//! querying, exporting and evaluating the scenes a local service trained.

pub mod bench;
pub mod eval;
pub mod export;
pub mod local;
pub mod models;
pub mod query;
pub mod render;
pub mod train;

use std::path::Path;

use anyhow::Context;
use segsplat::gpu::GpuContext;
use segsplat::scene::{LoadOptions, Scene, load_scene};

/// Loads a dataset directory (any supported format).
pub fn open_scene(dir: &Path) -> anyhow::Result<Scene> {
    load_scene(dir, &LoadOptions::default())
        .with_context(|| format!("cannot load the dataset in {}", dir.display()))
}

/// The best GPU adapter (hardware first, software Vulkan otherwise).
pub fn open_gpu() -> anyhow::Result<GpuContext> {
    let ctx = GpuContext::new_default().context("no usable GPU adapter")?;
    tracing::info!(
        adapter = %ctx.report.name,
        backend = %ctx.report.backend,
        float_atomics = ctx.report.float32_atomics,
        "GPU ready"
    );
    Ok(ctx)
}

/// Peak resident memory of this process in MiB (Linux `VmHWM`); on software adapters this
/// includes "GPU" memory.
pub fn peak_resident_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|line| line.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}
