//! What a render hands back ([`RenderOutput`]: the image and the state its backward pass
//! needs) and how one fails ([`RenderError`]).

use std::sync::Arc;

use super::workspace::{RenderWorkspace, WorkspacePool};
use crate::{RenderCamera, RenderSettings};
use segsplat_gpu::{GpuContext, GpuError};

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("gradient buffers hold {capacity} Gaussians but the scene has {count}")]
    GradsTooSmall { count: usize, capacity: usize },
    #[error(
        "grad_image holds {bytes} bytes but the render needs {needed} ({pixels} pixels x vec4<f32>)"
    )]
    GradImageTooSmall {
        bytes: u64,
        needed: u64,
        pixels: usize,
    },
    #[error("render still overflowed its intersection buffers after {attempts} attempts")]
    CapacityNotConverging { attempts: usize },
    #[error("camera image is empty ({width}x{height})")]
    EmptyImage { width: u32, height: u32 },
    #[error(transparent)]
    ObjectBatch(#[from] super::object_batch::ObjectBatchError),
    #[error(
        "a render needs {needed} tile intersections but one storage binding holds at most {limit}; \
         lower the resolution or the Gaussian count"
    )]
    IntersectionsExceedAdapter { needed: u64, limit: u64 },
}

/// A finished forward pass: the image and the state backward needs. Dropping it returns its
/// buffers to the renderer's pool.
#[derive(Debug)]
pub struct RenderOutput {
    pub(super) workspace: Option<RenderWorkspace>,
    pub(super) pool: Arc<WorkspacePool>,
    pub camera: RenderCamera,
    pub settings: RenderSettings,
    pub gaussian_count: u32,
}

impl Drop for RenderOutput {
    fn drop(&mut self) {
        if let Some(workspace) = self.workspace.take() {
            self.pool.give_back(workspace);
        }
    }
}

impl RenderOutput {
    pub(super) fn workspace(&self) -> &RenderWorkspace {
        // Only `drop` takes the workspace out.
        self.workspace
            .as_ref()
            .unwrap_or_else(|| unreachable!("workspace present until drop"))
    }

    /// `array<vec4<f32>>`, `width * height` entries row-major: rgb (background composited) and
    /// alpha. The buffer may be longer than the image; bind with [`RenderOutput::image_bytes`].
    pub fn image(&self) -> &wgpu::Buffer {
        &self.workspace().image
    }

    /// Projected splats, 3 vec4 per Gaussian (layout in `project_common.wgsl`; `[3 i + 1].w` is
    /// the screen radius in pixels, 0 when culled). Read by the densification statistics.
    pub fn projected(&self) -> &wgpu::Buffer {
        &self.workspace().projected
    }

    pub fn image_bytes(&self) -> u64 {
        self.camera.pixel_count() as u64 * 16
    }

    /// Per pixel final transmittance (1 - alpha), f32.
    pub fn final_transmittance(&self) -> &wgpu::Buffer {
        &self.workspace().final_transmittance
    }

    /// Per pixel sum of weight x camera depth, f32 (divide by alpha for the mean depth).
    pub fn depth(&self) -> &wgpu::Buffer {
        &self.workspace().depth
    }

    /// Reads the image back (tests, masks, evaluation; never inside a training step).
    pub fn read_image(&self, ctx: &GpuContext) -> Result<Vec<[f32; 4]>, GpuError> {
        let bytes = ctx.read_buffer(self.image(), self.image_bytes())?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    pub fn read_depth(&self, ctx: &GpuContext) -> Result<Vec<f32>, GpuError> {
        let bytes = ctx.read_buffer(self.depth(), self.camera.pixel_count() as u64 * 4)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// Intersections the render produced (unclamped) and its capacity: a read-back, for tests.
    pub fn read_intersection_count(&self, ctx: &GpuContext) -> Result<(u32, u32), GpuError> {
        let counts: Vec<u32> = ctx.read_vec(&self.workspace().counts)?;
        Ok((counts[5], self.workspace().size.intersections))
    }
}
