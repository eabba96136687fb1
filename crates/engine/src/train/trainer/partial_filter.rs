//! The partial-mask filter of Segment-then-Splat: every (object, view) pair rendered alone, once,
//! near the end of training, batched per view on that view's full render.

use super::{TrainError, Trainer};
use crate::render::ObjectSlot;
use crate::train::object_loss::{ObjectTargets, SkippedPair, rendered_mask_iou};
use crate::{ObjectFilter, RenderSettings};
use segsplat_scene::Level;

/// Object renders per batch (and submission) while filtering partial masks: bounds the batch's
/// images (slots x pixels) and tile keys.
const PARTIAL_FILTER_BATCH: usize = 16;

impl Trainer {
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
        let pairs = collect_pairs(targets);
        let mut newly_skipped = Vec::new();
        let full = RenderSettings {
            filter: ObjectFilter::All,
            background: [0.0; 3],
            sh_degree,
        };
        // Dynamic scenes: the geometry is deformed to each view's time before its renders.
        let mut deformed_time = None;
        for view_pairs in pairs.chunk_by(|a, b| a.train_view == b.train_view) {
            let view = &self.views.train[view_pairs[0].train_view];
            let camera = view.camera;
            let mut encoder = self.new_encoder("partial mask filter");
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
            let scene = super::dynamics::render_view(&self.gaussians, &self.dynamics);
            let base = self
                .renderer
                .forward(&self.ctx, &mut encoder, scene, &camera, &full)?;
            let mut pending = Some(encoder);
            for batch_pairs in view_pairs.chunks(PARTIAL_FILTER_BATCH) {
                let mut encoder = match pending.take() {
                    Some(encoder) => encoder,
                    None => self.new_encoder("partial mask filter"),
                };
                let slots: Vec<ObjectSlot> = batch_pairs
                    .iter()
                    .map(|pair| ObjectSlot {
                        level: pair.level,
                        id: pair.object_id,
                    })
                    .collect();
                let batch =
                    self.renderer
                        .forward_objects(&self.ctx, &mut encoder, scene, &base, &slots)?;
                self.ctx.queue.submit([encoder.finish()]);
                let images = batch.read_images(&self.ctx)?;
                for (pair, image) in batch_pairs.iter().zip(&images) {
                    let ids = &targets.views[pair.train_view].ids_cpu[pair.level.index()];
                    let alpha = image.iter().take(ids.len()).map(|pixel| pixel[3]);
                    if rendered_mask_iou(alpha, ids, pair.object_id) < threshold {
                        newly_skipped.push(*pair);
                    }
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

    fn new_encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }
}

/// Every (object, view) pair, grouped by view (the batches are per view).
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
