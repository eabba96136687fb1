//! Checkpoints: everything a trainer needs to continue exactly where it stopped, and the
//! trainer rebuilt from one.

use segsplat_gpu::GpuContext;
use segsplat_scene::Scene;

use super::{TrainError, Trainer, TrainerMeta};
use crate::checkpoint::Checkpoint;
use crate::densify::DensifyStats;
use crate::model::GaussianModel;

impl Trainer {
    /// Everything needed to continue exactly here, read back at once (the queue drained on
    /// this thread); [`Self::checkpoint_snapshot`] takes the same without waiting.
    pub fn checkpoint(&self) -> Result<Checkpoint<TrainerMeta>, TrainError> {
        let ctx = &self.ctx;
        let count = self.gaussians.count();
        let model = self.gaussians.download(ctx)?;
        let first = self.first_moments.download(ctx, count)?;
        let second = self.second_moments.download(ctx, count)?;
        let stats = self.accumulators.download(ctx, count)?;
        let field = match &self.dynamics {
            Some(dynamics) => {
                let field = &dynamics.field;
                Some([
                    field.read(ctx, &field.parameters)?,
                    field.read(ctx, &field.first_moment)?,
                    field.read(ctx, &field.second_moment)?,
                ])
            }
            None => None,
        };
        Ok(checkpoint_from_state(
            self.checkpoint_meta(),
            &model,
            &first,
            &second,
            &stats,
            field,
        ))
    }

    /// The host-side state a checkpoint records besides the arrays.
    pub(super) fn checkpoint_meta(&self) -> TrainerMeta {
        TrainerMeta {
            step: self.step,
            gaussians: self.gaussians.count(),
            rng: self.rng.clone(),
            view_queue: self.view_queue.clone(),
            intersection_capacity: self.renderer.intersection_capacity(),
            config: self.config.clone(),
            train_views: self.views.train.len(),
            skipped_pairs: self.skipped_pairs.iter().copied().collect(),
            gaussian_budget: Some(self.gaussian_budget),
            converged_at: self.converged_at(),
            partial_filter: self.partial_filter_report.clone(),
        }
    }

    /// A trainer continuing from `checkpoint` (same scene; the config it was made with).
    pub fn resume(
        ctx: &GpuContext,
        scene: &Scene,
        checkpoint: &Checkpoint<TrainerMeta>,
    ) -> Result<Self, TrainError> {
        let meta = &checkpoint.meta;
        let count = meta.gaussians;
        let mut model = get_model(checkpoint, "model", count)?;
        model.object_ids = checkpoint.get("object_ids")?;
        let first = get_model(checkpoint, "adam.m", count)?;
        let second = get_model(checkpoint, "adam.v", count)?;
        let stats = DensifyStats {
            gradient_sums: checkpoint.get("densify.gradient_sums")?,
            visible_counts: checkpoint.get("densify.visible_counts")?,
            max_radii: checkpoint.get("densify.max_radii")?,
        };
        let mut trainer = Self::new(ctx, scene, meta.config.clone(), Some(model.clone()))?;
        if trainer.views.train.len() != meta.train_views {
            return Err(TrainError::CheckpointMismatch(format!(
                "{} training views now, {} when saved",
                trainer.views.train.len(),
                meta.train_views
            )));
        }
        trainer.replace_state(&model, &first, &second, &stats)?;
        trainer.step = meta.step;
        trainer.rng = meta.rng.clone();
        trainer.view_queue = meta.view_queue.clone();
        trainer.skipped_pairs = meta.skipped_pairs.iter().copied().collect();
        trainer.partial_filter_report = meta.partial_filter.clone();
        trainer.fit_check.restore(meta.converged_at);
        if let Some(budget) = meta.gaussian_budget {
            trainer.gaussian_budget = budget;
        }
        trainer
            .renderer
            .set_intersection_capacity(meta.intersection_capacity);
        if let Some(dynamics) = &trainer.dynamics {
            let parameters: Vec<f32> = checkpoint.get("deform.parameters")?;
            let first: Vec<f32> = checkpoint.get("deform.m")?;
            let second: Vec<f32> = checkpoint.get("deform.v")?;
            dynamics.field.write_parameters(ctx, &parameters)?;
            dynamics.field.write_moments(ctx, &first, &second)?;
        }
        Ok(trainer)
    }
}

/// A checkpoint of `meta` and the arrays read back: the model (with object ids), the Adam
/// moments, the densification statistics and the deformation field's parameters and moments.
pub(super) fn checkpoint_from_state(
    meta: TrainerMeta,
    model: &GaussianModel,
    first: &GaussianModel,
    second: &GaussianModel,
    stats: &DensifyStats,
    field: Option<[Vec<f32>; 3]>,
) -> Checkpoint<TrainerMeta> {
    let mut checkpoint = Checkpoint::new(meta);
    put_model(&mut checkpoint, "model", model);
    put_model(&mut checkpoint, "adam.m", first);
    put_model(&mut checkpoint, "adam.v", second);
    checkpoint.put("object_ids", &model.object_ids);
    checkpoint.put("densify.gradient_sums", &stats.gradient_sums);
    checkpoint.put("densify.visible_counts", &stats.visible_counts);
    checkpoint.put("densify.max_radii", &stats.max_radii);
    if let Some([parameters, first, second]) = field {
        checkpoint.put("deform.parameters", &parameters);
        checkpoint.put("deform.m", &first);
        checkpoint.put("deform.v", &second);
    }
    checkpoint
}

fn put_model(checkpoint: &mut Checkpoint<TrainerMeta>, prefix: &str, model: &GaussianModel) {
    checkpoint.put(&format!("{prefix}.means"), &model.means);
    checkpoint.put(&format!("{prefix}.log_scales"), &model.log_scales);
    checkpoint.put(&format!("{prefix}.rotations"), &model.rotations);
    checkpoint.put(&format!("{prefix}.opacity_logits"), &model.opacity_logits);
    checkpoint.put(&format!("{prefix}.sh"), &model.sh_coefficients);
}

fn get_model(
    checkpoint: &Checkpoint<TrainerMeta>,
    prefix: &str,
    count: usize,
) -> Result<GaussianModel, TrainError> {
    let model = GaussianModel {
        means: checkpoint.get(&format!("{prefix}.means"))?,
        log_scales: checkpoint.get(&format!("{prefix}.log_scales"))?,
        rotations: checkpoint.get(&format!("{prefix}.rotations"))?,
        opacity_logits: checkpoint.get(&format!("{prefix}.opacity_logits"))?,
        sh_coefficients: checkpoint.get(&format!("{prefix}.sh"))?,
        object_ids: vec![[crate::OBJECT_NONE; 3]; count],
    };
    if model.means.len() != count {
        return Err(TrainError::CheckpointMismatch(format!(
            "{prefix}: {} Gaussians stored, header says {count}",
            model.means.len()
        )));
    }
    Ok(model)
}
