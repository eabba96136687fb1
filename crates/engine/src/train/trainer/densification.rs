//! The trainer's adaptive density control: densification within the Gaussian budget and the
//! opacity reset, read back and re-laid out on the CPU (every `densify_interval` steps), and
//! the upload of a new model with its optimiser moments.

use super::{TrainError, Trainer, grown_capacity};
use crate::densify::{self, DensifyPlan, DensifyStats, PruneGuard};
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

    /// Densification and/or opacity reset: read back, re-lay out on the CPU, upload.
    pub(super) fn densify_and_reset(&mut self, step: u32) -> Result<(), TrainError> {
        let ctx = self.ctx.clone();
        let count = self.gaussians.count();
        let mut model = self.gaussians.download(&ctx)?;
        let mut first = self.first_moments.download(&ctx, count)?;
        let mut second = self.second_moments.download(&ctx, count)?;
        if self.schedule.densifies_at(step) {
            let stats = self.accumulators.download(&ctx, count)?;
            let mut config = self.config.densify.clone();
            if self.schedule.prunes_oversized_at(step) {
                config.max_world_scale_fraction.get_or_insert(0.1);
                config.max_screen_radius_fraction.get_or_insert(0.15);
            }
            // Grow only into what is left of the budget; pruning still runs at full budget.
            let room = self.gaussian_limit().saturating_sub(count);
            let plan = densify::plan_densification(
                &model,
                &stats,
                &config,
                self.scene_extent,
                self.prune_guard.as_deref().map(|g| g as &dyn PruneGuard),
                Some(room),
                &mut self.rng,
            );
            tracing::debug!(
                step,
                cloned = plan.cloned,
                split = plan.split,
                pruned = plan.pruned,
                spared = plan.spared,
                "densified"
            );
            model = plan.apply(&model, config.split_children);
            first = gather_fresh_zero(&plan, &first);
            second = gather_fresh_zero(&plan, &second);
        }
        if self.schedule.resets_opacity_at(step) {
            densify::reset_opacity_logits(&mut model.opacity_logits, 0.01);
            first.opacity_logits.iter_mut().for_each(|m| *m = 0.0);
            second.opacity_logits.iter_mut().for_each(|v| *v = 0.0);
        }
        self.replace_state(&model, &first, &second, &DensifyStats::default())?;
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
        } else {
            self.gaussians.write(&ctx, model)?;
        }
        self.first_moments.write(&ctx, first)?;
        self.second_moments.write(&ctx, second)?;
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("densify reset"),
            });
        self.accumulators.encode_clear(&mut encoder);
        ctx.submit(encoder.finish());
        if !stats.gradient_sums.is_empty() {
            self.accumulators.upload(&ctx, stats);
        }
        Ok(())
    }
}

/// Optimiser moments re-laid out by `plan`: kept rows keep theirs, new rows start at zero.
fn gather_fresh_zero(plan: &DensifyPlan, rows: &GaussianModel) -> GaussianModel {
    GaussianModel {
        means: plan.gather(&rows.means, |_| [0.0; 3]),
        log_scales: plan.gather(&rows.log_scales, |_| [0.0; 3]),
        rotations: plan.gather(&rows.rotations, |_| [0.0; 4]),
        opacity_logits: plan.gather(&rows.opacity_logits, |_| 0.0),
        sh_coefficients: plan.gather(&rows.sh_coefficients, |_| Default::default()),
        object_ids: Vec::new(),
    }
}
