//! Releasing a GPU context at shutdown, in a defined order and on a thread that waits for it.
//!
//! On NVIDIA's Vulkan driver a process whose device was still alive, or still being destroyed
//! by another thread, when `exit` ran the driver's own exit handlers died with SIGSEGV after a
//! clean stop (issue 39, defect 5; upstream gfx-rs/wgpu#8365). So a stopping service releases
//! every context itself: the buffers and pipelines built on it first (their owners drop them),
//! then, once nothing else holds the context, the work submitted to its queue is finished and
//! the cached bind groups, the uniform ring, the queue and the device are dropped here, before
//! the process exits.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::GpuContext;

/// How often [`sole_owner`] looks whether the other holders have let go.
const POLL_EVERY: Duration = Duration::from_millis(10);

/// `shared`'s value once this is its last handle, waiting up to `wait` for the others (a job
/// stage or a render still running) to drop theirs; `Err` hands it back when they did not.
pub fn sole_owner<T>(shared: Arc<T>, wait: Duration) -> Result<T, Arc<T>> {
    let deadline = Instant::now() + wait;
    let mut shared = shared;
    loop {
        match Arc::try_unwrap(shared) {
            Ok(value) => return Ok(value),
            Err(still_shared) if Instant::now() >= deadline => return Err(still_shared),
            Err(still_shared) => shared = still_shared,
        }
        std::thread::sleep(POLL_EVERY);
    }
}

/// Releases `ctx` here once nothing else holds it (see [`sole_owner`]): finishes the work its
/// queue has (for at most `wait`), then drops the kernel profiler's buffers, the queue and the
/// device, in that order. `Err` hands the context back when others still hold it after `wait`.
pub fn release_context(ctx: Arc<GpuContext>, wait: Duration) -> Result<(), Arc<GpuContext>> {
    let started = Instant::now();
    let ctx = sole_owner(ctx, wait)?;
    let left = wait.saturating_sub(started.elapsed()).max(POLL_EVERY);
    // A lost or hung device cannot finish its work; dropping it is all that is left, so the
    // poll's error only bounds the wait.
    let _ = ctx.device.poll(wgpu::PollType::Wait {
        submission_index: None,
        timeout: Some(left),
    });
    let GpuContext {
        device,
        queue,
        profiler,
        uniforms,
        bind_groups,
        kernels,
        ..
    } = ctx;
    // Cached bind groups hold the last references to buffers of scenes and models: first. The
    // compiled kernels' pipelines go with them, before the device.
    drop(bind_groups);
    drop(kernels);
    drop(uniforms);
    drop(profiler);
    drop(queue);
    drop(device);
    Ok(())
}
