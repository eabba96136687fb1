//! A dynamic scene on the serving GPU: its deformation field and the geometry it last moved the
//! canonical Gaussians to, so masks and object positions can be asked for at any time `t`.

use super::ServingError;
use segsplat_engine::deform::{DeformationField, DeformedGeometry, StoredDeformation};
use segsplat_engine::model::GaussianView;
use segsplat_engine::{GaussianModel, GpuGaussians};
use segsplat_gpu::GpuContext;

/// Gaussians whose field activations are held at once while serving.
const SERVING_CHUNK: usize = 65_536;

pub struct SceneMotion {
    field: DeformationField,
    geometry: DeformedGeometry,
    /// The canonical model (appearance and ids) for summaries at a time.
    canonical: GaussianModel,
    pub time_range: [f32; 2],
    deformed_at: Option<f32>,
}

fn gpu_error(error: impl std::fmt::Display) -> ServingError {
    ServingError::Gpu(error.to_string())
}

impl SceneMotion {
    pub fn new(
        ctx: &GpuContext,
        stored: &StoredDeformation,
        canonical: GaussianModel,
    ) -> Result<Self, ServingError> {
        Ok(Self {
            field: DeformationField::new(
                ctx,
                stored.header.field,
                &stored.parameters,
                SERVING_CHUNK,
            )
            .map_err(gpu_error)?,
            geometry: DeformedGeometry::new(ctx, canonical.len()).map_err(gpu_error)?,
            time_range: stored.header.time_range,
            canonical,
            deformed_at: None,
        })
    }

    /// GPU bytes beyond the Gaussians: the moved geometry (10 f32 per Gaussian) and the field.
    pub fn extra_bytes(&self) -> u64 {
        self.canonical.len() as u64 * 40 + self.field.parameter_count() as u64 * 16
    }

    /// Moves the Gaussians to `time` (no-op when they are there already) and returns what a
    /// render at that time reads.
    pub fn at<'a>(
        &'a mut self,
        ctx: &GpuContext,
        gaussians: &'a GpuGaussians,
        time: f32,
    ) -> Result<GaussianView<'a>, ServingError> {
        if !time.is_finite() {
            return Err(ServingError::BadView(format!("time {time} must be finite")));
        }
        if self.deformed_at != Some(time) {
            let mut encoder = segsplat_gpu::Encoder::new(ctx, "deform for serving");
            self.field
                .encode_forward(ctx, &mut encoder, gaussians, &self.geometry, time)
                .map_err(gpu_error)?;
            ctx.submit_untimed(encoder.finish());
            self.deformed_at = Some(time);
        }
        Ok(self.geometry.view(gaussians))
    }

    /// The scene's Gaussians as they are at `time` (positions, scales and rotations moved).
    pub fn model_at(
        &mut self,
        ctx: &GpuContext,
        gaussians: &GpuGaussians,
        time: f32,
    ) -> Result<GaussianModel, ServingError> {
        self.at(ctx, gaussians, time)?;
        let mut model = self.canonical.clone();
        self.geometry
            .read_into(ctx, &mut model)
            .map_err(gpu_error)?;
        Ok(model)
    }
}
