//! Compiling a trainer's kernels before it is built (issue 38, item 5).
//!
//! A job's trainer can only be built once the masks are made (it uploads them), but its kernels
//! need nothing from the scene: a job compiles them into the context's kernel cache
//! (`segsplat_gpu::kernel_cache`) on another thread while its masks are made, and the trainer
//! then finds every one compiled. On a GPU the driver's compiles are CPU work the masks' cores
//! can share; a worker's later jobs find the cache warm anyway.

use super::{TrainError, Trainer};
use crate::adam::{Adam, AdamSettings};
use crate::deform::{DeformKernels, GemmKernel};
use crate::densify::gpu::GpuDensifier;
use crate::loss::RenderLoss;
use crate::render::Renderer;
use crate::train::config::TrainConfig;
use crate::train::densify_stats::DensifyAccumulators;
use crate::train::mask_iou::MaskIouCounts;
use segsplat_gpu::{GpuContext, KernelCompiles};

impl Trainer {
    /// Compiles the kernels a trainer for `config` builds (rendering, loss, Adam,
    /// densification, and the object loss's and the deformation field's when configured) into
    /// `ctx`'s kernel cache, and says what that compiled. Builds no scene and keeps nothing but
    /// the compiled kernels.
    pub fn compile_kernels(
        ctx: &GpuContext,
        config: &TrainConfig,
    ) -> Result<KernelCompiles, TrainError> {
        let before = ctx.kernel_compiles();
        Renderer::new(ctx)?;
        RenderLoss::new(ctx)?;
        Adam::new(ctx, AdamSettings::default())?;
        GpuDensifier::new(ctx)?;
        DensifyAccumulators::new(ctx, 1)?;
        if config.object_loss.is_some() {
            MaskIouCounts::new(ctx, 1)?;
        }
        if config.deformation.is_some() {
            DeformKernels::with_gemm(ctx, GemmKernel::for_adapter(ctx))?;
        }
        Ok(ctx.kernel_compiles().since(&before))
    }
}
