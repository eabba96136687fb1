//! The trainer's adaptive density control: densification within the Gaussian budget and the
//! opacity reset on the GPU (every `densify_interval` steps), and the upload of a new model
//! with its optimiser moments (a resumed checkpoint).

use super::{TrainError, Trainer, grown_capacity};
use rand::Rng;

use crate::densify::gpu::{DensifyInput, DensifyRequest};
use crate::densify::{DensifyStats, PruneGuard};
use crate::model::{
    GaussianModel, GaussianParameterBuffers, GpuGaussianGrads, GpuGaussians,
    max_gaussians_for_adapter,
};
use crate::train::densify_stats::DensifyAccumulators;

impl Trainer {
    /// Most Gaussians densification may grow to: the budget, within the configured maximum and
    /// what the adapter can hold.
    pub fn gaussian_limit(&self) -> usize {
        self.gaussian_budget
            .min(self.config.max_gaussians)
            .min(max_gaussians_for_adapter(&self.ctx))
    }

    /// The Gaussian budget of this job (the config's, or the scene's:
    /// [`crate::train::budget::scene_gaussian_budget`]).
    pub fn gaussian_budget(&self) -> usize {
        self.gaussian_budget
    }

    /// Densification and/or opacity reset, on the GPU ([`crate::densify::gpu`]): the host
    /// reads back four counts; the accumulators start again from zero.
    pub(super) fn densify_and_reset(&mut self, step: u32) -> Result<(), TrainError> {
        let ctx = self.ctx.clone();
        if self.schedule.densifies_at(step) {
            let mut config = self.config.densify.clone();
            if self.schedule.prunes_oversized_at(step) {
                config.max_world_scale_fraction.get_or_insert(0.1);
                config.max_screen_radius_fraction.get_or_insert(0.15);
            }
            // Grow only into what is left of the budget; pruning still runs at full budget.
            let room = self.gaussian_limit().saturating_sub(self.gaussians.count());
            let ceiling = self.config.max_gaussians.min(self.gaussian_budget);
            let request = DensifyRequest {
                config: &config,
                scene_extent: self.scene_extent,
                guard: self.prune_guard.as_deref().map(|g| g as &dyn PruneGuard),
                max_new: Some(room),
                seed: self.rng.random(),
            };
            let input = DensifyInput {
                gaussians: &self.gaussians,
                first_moments: &self.first_moments,
                second_moments: &self.second_moments,
                stats: self.accumulators.buffers(),
            };
            let densified = self.densifier.densify(&ctx, &input, &request, |needed| {
                grown_capacity(&ctx, needed, ceiling)
            })?;
            let summary = densified.summary;
            tracing::debug!(
                step,
                cloned = summary.cloned,
                split = summary.split,
                pruned = summary.pruned,
                spared = summary.spared,
                "densified"
            );
            let capacity = densified.gaussians.capacity();
            if capacity > self.grads.capacity() {
                self.grads = GpuGaussianGrads::new(&ctx, capacity)?;
                self.accumulators = DensifyAccumulators::new(&ctx, capacity)?;
            }
            self.gaussians = densified.gaussians;
            self.first_moments = densified.first_moments;
            self.second_moments = densified.second_moments;
            // The replaced buffers are now held only by cached bind groups: free them now.
            ctx.release_cached_bind_groups();
        }
        if self.schedule.resets_opacity_at(step) {
            self.densifier.reset_opacity(
                &ctx,
                &self.gaussians,
                &self.first_moments,
                &self.second_moments,
                0.01,
            );
        }
        let mut encoder = segsplat_gpu::Encoder::new(&ctx, "densify clear");
        self.accumulators.encode_clear(&mut encoder);
        ctx.submit(encoder.finish());
        Ok(())
    }

    /// Uploads a new model with its optimiser moments, growing buffers when needed.
    pub(super) fn replace_state(
        &mut self,
        model: &GaussianModel,
        first: &GaussianModel,
        second: &GaussianModel,
        stats: &DensifyStats,
    ) -> Result<(), TrainError> {
        let ctx = self.ctx.clone();
        let count = model.len();
        if count > self.gaussians.capacity() {
            let capacity = grown_capacity(
                &ctx,
                count,
                self.config.max_gaussians.min(self.gaussian_budget),
            );
            self.gaussians = GpuGaussians::upload(&ctx, model, capacity)?;
            self.grads = GpuGaussianGrads::new(&ctx, capacity)?;
            self.first_moments = GaussianParameterBuffers::new(&ctx, "adam.m", capacity)?;
            self.second_moments = GaussianParameterBuffers::new(&ctx, "adam.v", capacity)?;
            self.accumulators = DensifyAccumulators::new(&ctx, capacity)?;
            ctx.release_cached_bind_groups();
        } else {
            self.gaussians.write(&ctx, model)?;
        }
        self.first_moments.write(&ctx, first)?;
        self.second_moments.write(&ctx, second)?;
        let mut encoder = segsplat_gpu::Encoder::new(&ctx, "densify reset");
        self.accumulators.encode_clear(&mut encoder);
        ctx.submit(encoder.finish());
        if !stats.gradient_sums.is_empty() {
            self.accumulators.upload(&ctx, stats);
        }
        Ok(())
    }
}
