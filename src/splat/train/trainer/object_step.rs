//! The trainer's Segment-then-Splat extension: object renders inside each step, and the
//! partial-mask filter (see [`crate::splat::train::object_loss`]).

use super::{TrainError, Trainer};
use crate::scene::Level;
use crate::splat::loss::{LossImages, LossOutputs, ObjectMask};
use crate::splat::train::object_loss::{
    ObjectTargets, SkippedPair, rendered_mask_iou, sample_objects,
};
use crate::splat::{ObjectFilter, RenderSettings};

/// Object renders recorded per submission while filtering partial masks (bounds the number of
/// render workspaces alive at once).
const PARTIAL_FILTER_BATCH: usize = 16;

#[derive(Debug, thiserror::Error)]
pub enum ObjectTargetsError {
    #[error(
        "object masks are given for {given} views but the trainer has {expected} training views"
    )]
    ViewCount { given: usize, expected: usize },
    #[error(
        "training view {view}: {level:?} object mask has {given} pixels, the view has {expected}"
    )]
    PixelCount {
        view: usize,
        level: Level,
        given: usize,
        expected: usize,
    },
}

impl Trainer {
    /// Gives the trainer each training view's object masks (in [`Trainer::views`]'s training
    /// order, at the training resolution), which turns on the object loss configured in
    /// `TrainConfig::object_loss`.
    pub fn set_object_targets(&mut self, targets: ObjectTargets) -> Result<(), TrainError> {
        let expected = self.views.train.len();
        if targets.views.len() != expected {
            return Err(TrainError::ObjectTargets(ObjectTargetsError::ViewCount {
                given: targets.views.len(),
                expected,
            }));
        }
        for (view, (masks, train_view)) in targets.views.iter().zip(&self.views.train).enumerate() {
            let pixels = train_view.camera.pixel_count();
            for level in Level::ALL {
                let given = masks.ids_cpu[level.index()].len();
                if given != pixels {
                    return Err(TrainError::ObjectTargets(ObjectTargetsError::PixelCount {
                        view,
                        level,
                        given,
                        expected: pixels,
                    }));
                }
            }
        }
        self.object_targets = Some(targets);
        Ok(())
    }

    /// (object, view) pairs the partial-mask filter has left out so far, sorted.
    pub fn skipped_pairs(&self) -> Vec<SkippedPair> {
        self.skipped_pairs.iter().copied().collect()
    }

    /// Records the object renders of one step: for each active level, `m` objects of the view
    /// rendered alone on black, each with its own loss slot, backward adding into the gradients.
    pub(super) fn encode_object_losses(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        view_index: usize,
        sh_degree: u32,
    ) -> Result<(), TrainError> {
        let (Some(config), Some(targets)) = (&self.config.object_loss, &self.object_targets) else {
            return Ok(());
        };
        let masks = &targets.views[view_index];
        let view = &self.views.train[view_index];
        let mut slot = 1;
        for level in config.active_levels(self.step, self.config.steps) {
            let skipped = &self.skipped_pairs;
            let objects = sample_objects(
                &masks.present[level.index()],
                config.objects_per_level,
                |object_id| {
                    skipped.contains(&SkippedPair {
                        train_view: view_index,
                        level,
                        object_id,
                    })
                },
                &mut self.rng,
            );
            for object_id in objects {
                let settings = RenderSettings {
                    filter: ObjectFilter::Object {
                        level,
                        id: object_id,
                    },
                    background: [0.0; 3],
                    sh_degree,
                };
                let scene = super::dynamics::render_view(&self.gaussians, &self.dynamics);
                let output =
                    self.renderer
                        .forward(&self.ctx, encoder, scene, &view.camera, &settings)?;
                self.loss.encode(
                    &self.ctx,
                    encoder,
                    &LossImages {
                        rendered: output.image(),
                        target: &view.target,
                        target_mask: Some(ObjectMask {
                            object_ids: &masks.ids[level.index()],
                            object_id,
                        }),
                        width: view.camera.width,
                        height: view.camera.height,
                    },
                    config.weight,
                    &LossOutputs {
                        rendered_grad: &self.grad_image,
                        loss_values: &self.loss_values,
                        loss_slot: slot,
                    },
                )?;
                self.renderer.backward(
                    &self.ctx,
                    encoder,
                    scene,
                    &output,
                    &self.grad_image,
                    &mut self.grads,
                )?;
                slot += 1;
            }
        }
        Ok(())
    }

    /// Whether the partial-mask filter runs after `step`.
    pub(super) fn partial_filter_due(&self, step: u32) -> bool {
        match (&self.config.object_loss, &self.object_targets) {
            (Some(config), Some(_)) => step == config.partial_filter_step(self.config.steps),
            _ => false,
        }
    }

    /// Renders every (object, view) pair alone and leaves out those whose rendered mask
    /// (alpha > 0.5) has IoU below the threshold with the 2D mask: that mask shows the object
    /// only in part (occluded or cut), and fitting it would carve the object. Runs once, at the
    /// configured point of training; its read-backs are the one CPU round trip it costs.
    pub(super) fn filter_partial_masks(&mut self, sh_degree: u32) -> Result<(), TrainError> {
        let (Some(config), Some(targets)) = (&self.config.object_loss, &self.object_targets) else {
            return Ok(());
        };
        let threshold = config.partial_iou_threshold;
        let pairs: Vec<SkippedPair> = collect_pairs(targets);
        let mut newly_skipped = Vec::new();
        // Dynamic scenes: the geometry is deformed to each view's time before its renders.
        let mut deformed_time = None;
        for batch in pairs.chunks(PARTIAL_FILTER_BATCH) {
            let mut encoder =
                self.ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("partial mask filter"),
                    });
            let mut outputs = Vec::with_capacity(batch.len());
            for pair in batch {
                let settings = RenderSettings {
                    filter: ObjectFilter::Object {
                        level: pair.level,
                        id: pair.object_id,
                    },
                    background: [0.0; 3],
                    sh_degree,
                };
                let view = &self.views.train[pair.train_view];
                let camera = view.camera;
                if self.dynamics.is_some() && deformed_time != Some(view.time) {
                    super::dynamics::deform_to(
                        &self.ctx,
                        self.step,
                        &mut self.dynamics,
                        &self.gaussians,
                        &mut encoder,
                        view.time,
                    )?;
                    deformed_time = Some(view.time);
                }
                outputs.push(self.renderer.forward(
                    &self.ctx,
                    &mut encoder,
                    super::dynamics::render_view(&self.gaussians, &self.dynamics),
                    &camera,
                    &settings,
                )?);
            }
            self.ctx.queue.submit([encoder.finish()]);
            for (pair, output) in batch.iter().zip(&outputs) {
                let image = output.read_image(&self.ctx)?;
                let ids = &targets.views[pair.train_view].ids_cpu[pair.level.index()];
                let alpha = image.iter().take(ids.len()).map(|pixel| pixel[3]);
                if rendered_mask_iou(alpha, ids, pair.object_id) < threshold {
                    newly_skipped.push(*pair);
                }
            }
        }
        tracing::info!(
            checked = pairs.len(),
            skipped = newly_skipped.len(),
            "partial-mask filter"
        );
        self.skipped_pairs.extend(newly_skipped);
        Ok(())
    }
}

fn collect_pairs(targets: &ObjectTargets) -> Vec<SkippedPair> {
    targets
        .views
        .iter()
        .enumerate()
        .flat_map(|(train_view, masks)| {
            Level::ALL.into_iter().flat_map(move |level| {
                masks.present[level.index()]
                    .iter()
                    .map(move |&object_id| SkippedPair {
                        train_view,
                        level,
                        object_id,
                    })
            })
        })
        .collect()
}
