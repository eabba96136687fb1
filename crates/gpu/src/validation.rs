//! Turning wgpu validation failures into errors.
//!
//! wgpu's default uncaptured-error handler panics. Pipeline and bind-group creation happen on
//! request paths (a worker building its kernels), so they run inside a validation error scope and a
//! failure becomes a [`GpuError`] naming what was being built.

use crate::{GpuContext, GpuError};

/// Runs `build` inside a validation error scope; any validation error it caused becomes
/// `GpuError::Device` prefixed with `what`.
pub fn validated<T>(
    ctx: &GpuContext,
    what: &str,
    build: impl FnOnce() -> T,
) -> Result<T, GpuError> {
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let value = build();
    match pollster::block_on(scope.pop()) {
        Some(error) => Err(GpuError::Device(format!("{what}: {error}"))),
        None => Ok(value),
    }
}
