//! The GPU's part of a stopping service (issue 39, defect 5).
//!
//! On NVIDIA's Vulkan driver a clean stop ("segsplat stopped") was followed by SIGSEGV: GPU
//! objects were left to whichever thread dropped the last handle, possibly while `exit` was
//! already running the driver's own exit handlers (gfx-rs/wgpu#8365). A stopping service
//! therefore releases everything on the GPU itself, in a defined order, after the listeners and
//! the workers have stopped and before it logs "segsplat stopped": the mask renderer's cached
//! scenes, its renderer and then its device; then the workers' devices, after the job stages'
//! buffers and pipelines are gone. No GPU object lives in a static, so none is left to a static
//! destructor.

use std::sync::Arc;
use std::time::Duration;

use tracing::{info, warn};

use segsplat_gpu::{GpuContext, release_context};
use segsplat_service::core::ServiceCore;
use segsplat_service::serving::GpuRelease;

/// How long each of the two releases waits for renders or job stages still running (past the
/// workers' grace) to let go of the GPU; what they still hold then is theirs to drop.
const GPU_RELEASE_WAIT: Duration = Duration::from_secs(3);

/// Releases the mask renderer's GPU, then `worker_gpus`, on a blocking thread it waits for (the
/// waits poll and the drops may block on the device).
pub async fn release_gpus(core: &ServiceCore, worker_gpus: Vec<Arc<GpuContext>>) {
    let core = core.clone();
    let released = tokio::task::spawn_blocking(move || {
        match core.serving.cache().release_gpu(GPU_RELEASE_WAIT) {
            GpuRelease::NeverOpened => {}
            GpuRelease::Released => info!("mask rendering GPU released"),
            GpuRelease::StillHeld => warn!(
                wait_secs = GPU_RELEASE_WAIT.as_secs_f64(),
                "the mask rendering GPU is still in use by a render; it is dropped when that \
                 render ends"
            ),
        }
        for ctx in worker_gpus {
            let adapter = ctx.report.name.clone();
            match release_context(ctx, GPU_RELEASE_WAIT) {
                Ok(()) => info!(%adapter, "worker GPU released"),
                Err(_) => warn!(
                    %adapter,
                    wait_secs = GPU_RELEASE_WAIT.as_secs_f64(),
                    "a worker GPU is still in use by a job stage; it is dropped when that stage \
                     ends"
                ),
            }
        }
    })
    .await;
    if let Err(error) = released {
        warn!(%error, "releasing the GPU failed");
    }
}
