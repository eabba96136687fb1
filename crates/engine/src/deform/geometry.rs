//! The deformed geometry a render reads at one time: moved means, log-scales and rotations, with
//! the canonical opacity, colour and object ids (the deformation never touches those, which is
//! why object ids stay aligned at every time).

use crate::model::GaussianView;
use crate::{GaussianModel, GpuGaussians};
use segsplat_gpu::{GpuContext, GpuError};

#[derive(Debug)]
pub struct DeformedGeometry {
    pub means: wgpu::Buffer,
    pub log_scales: wgpu::Buffer,
    pub rotations: wgpu::Buffer,
    capacity: usize,
}

fn buffer(ctx: &GpuContext, label: &str, words: usize) -> Result<wgpu::Buffer, GpuError> {
    ctx.storage_buffer(label, words as u64 * 4)
}

impl DeformedGeometry {
    pub fn new(ctx: &GpuContext, capacity: usize) -> Result<Self, GpuError> {
        Ok(Self {
            means: buffer(ctx, "deformed.means", 3 * capacity)?,
            log_scales: buffer(ctx, "deformed.log_scales", 3 * capacity)?,
            rotations: buffer(ctx, "deformed.rotations", 4 * capacity)?,
            capacity,
        })
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The scene as a render sees it: this geometry over `canonical`'s appearance and ids.
    pub fn view<'a>(&'a self, canonical: &'a GpuGaussians) -> GaussianView<'a> {
        let mut view = canonical.view();
        view.means = &self.means;
        view.log_scales = &self.log_scales;
        view.rotations = &self.rotations;
        view.capacity = view.capacity.min(self.capacity);
        view
    }

    /// Overwrites the first `model.len()` Gaussians' means, log-scales and rotations with this
    /// geometry (read back; waits for submitted work).
    pub fn read_into(&self, ctx: &GpuContext, model: &mut GaussianModel) -> Result<(), GpuError> {
        let means: Vec<[f32; 3]> = ctx.read_vec(&self.means)?;
        let log_scales: Vec<[f32; 3]> = ctx.read_vec(&self.log_scales)?;
        let rotations: Vec<[f32; 4]> = ctx.read_vec(&self.rotations)?;
        let count = model.len();
        model.means.copy_from_slice(&means[..count]);
        model.log_scales.copy_from_slice(&log_scales[..count]);
        model.rotations.copy_from_slice(&rotations[..count]);
        Ok(())
    }
}
