//! The partial-mask filter of Segment-then-Splat: every (object, view) pair rendered alone, once,
//! near the end of training, batched per view on that view's full render.

use super::{StopCheck, TrainError, Trainer};
use crate::render::{ObjectSlot, RENDER_ATTEMPTS, RenderError};
use crate::train::mask_iou::MaskIouCounts;
use crate::train::object_loss::{ObjectTargets, SkippedPair};
use crate::train::partial_filter_report::PartialFilterReport;
use crate::{ObjectFilter, RenderSettings};
use segsplat_gpu::GpuContext;
use segsplat_scene::Level;

/// Most object renders per batch while filtering partial masks.
const PARTIAL_FILTER_MAX_BATCH: usize = 64;

/// The batch's images may fill at most this share of one storage binding.
const BATCH_IMAGE_SHARE_OF_BINDING: u64 = 2;

impl Trainer {
    /// Has the partial-mask filter ask `check` between views and end the step with
    /// [`TrainError::Stopped`] when it says yes: the filter renders every (object, view) pair in
    /// one step, minutes on a large capture, where a stopping job could not be heard otherwise.
    /// The stopped step leaves no skipped pairs: a run resumed from the last checkpoint (before
    /// the filter's step) filters again.
    pub fn set_stop_check(&mut self, check: StopCheck) {
        self.stop_check = Some(check);
    }

    /// Whether the partial-mask filter runs after `step`.
    pub(super) fn partial_filter_due(&self, step: u32) -> bool {
        self.object_targets.is_some() && self.partial_filter_step() == Some(step)
    }

    /// Renders every (object, view) pair alone and leaves out those whose rendered mask
    /// (alpha > 0.5) has IoU below the threshold with the 2D mask: that mask shows the object
    /// only in part (occluded or cut), and fitting it would carve the object. Runs once, at the
    /// configured point of training. The overlaps are counted on the GPU; a view whose renders
    /// overflowed the intersection buffers is rendered again with the grown capacity, and the
    /// counts of every pair come back in one read-back at the end.
    pub(super) fn filter_partial_masks(&mut self, sh_degree: u32) -> Result<(), TrainError> {
        let (Some(config), Some(targets)) = (&self.config.object_loss, &self.object_targets) else {
            return Ok(());
        };
        let started = std::time::Instant::now();
        let dispatches_before = segsplat_gpu::dispatches_on_this_thread();
        let threshold = config.partial_iou_threshold;
        let (pairs, mask_pixels) = collect_pairs(targets);
        let counts = MaskIouCounts::new(&self.ctx, pairs.len())?;
        // A pending report of the training steps' renders is not the filter's.
        self.renderer.sync_capacity(&self.ctx)?;
        let full = RenderSettings {
            filter: ObjectFilter::All,
            background: [0.0; 3],
            sh_degree,
        };
        let mut first_pair = 0;
        let mut rerendered_views = 0;
        // Halved for the rest of the filter whenever a batch needs more tile intersections than
        // one storage binding holds.
        let mut intersection_bound = PARTIAL_FILTER_MAX_BATCH;
        // Dynamic scenes: the time the geometry is deformed to (it stays so across submissions).
        let mut deformed_time = None;
        for view_pairs in pairs.chunk_by(|a, b| a.train_view == b.train_view) {
            if self.stop_check.as_ref().is_some_and(|stop| stop()) {
                return Err(TrainError::Stopped { step: self.step });
            }
            let view = &self.views.train[view_pairs[0].train_view];
            let ids = targets.views[view_pairs[0].train_view].ids.each_ref();
            let memory_batch = memory_batch_size(&self.ctx, view.camera.pixel_count());
            let mut overflows = 0;
            loop {
                let batch_size = memory_batch.min(intersection_bound);
                let mut encoder = self.new_encoder("partial mask filter");
                counts.encode_clear(&mut encoder, first_pair, view_pairs.len());
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
                let base =
                    self.renderer
                        .forward(&self.ctx, &mut encoder, scene, &view.camera, &full)?;
                for (index, batch_pairs) in view_pairs.chunks(batch_size).enumerate() {
                    let slots: Vec<ObjectSlot> = batch_pairs
                        .iter()
                        .map(|pair| ObjectSlot {
                            level: pair.level,
                            id: pair.object_id,
                        })
                        .collect();
                    let batch = self.renderer.forward_objects(
                        &self.ctx,
                        &mut encoder,
                        scene,
                        &base,
                        &slots,
                    )?;
                    counts.encode_batch(
                        &self.ctx,
                        &mut encoder,
                        &batch,
                        ids,
                        first_pair + index * batch_size,
                    );
                }
                drop(base);
                self.ctx.submit(encoder.finish());
                match self.renderer.sync_capacity_to_retry(&self.ctx) {
                    Ok(report) if !report.overflowed => break,
                    // The capacity has grown to fit: render the view again.
                    Ok(_) => {
                        overflows += 1;
                        if overflows == RENDER_ATTEMPTS {
                            let attempts = overflows;
                            return Err(RenderError::CapacityNotConverging { attempts }.into());
                        }
                    }
                    Err(RenderError::IntersectionsExceedAdapter { .. }) if batch_size > 1 => {
                        intersection_bound = batch_size / 2;
                    }
                    Err(error) => return Err(error.into()),
                }
                rerendered_views += 1;
            }
            first_pair += view_pairs.len();
        }
        let overlaps = counts.read_overlaps(&self.ctx)?;
        let (newly_skipped, report) =
            PartialFilterReport::judge(self.step, threshold, &pairs, &mask_pixels, &overlaps);
        tracing::info!(
            checked = pairs.len(),
            skipped = newly_skipped.len(),
            skipped_rendering_nothing = report.skipped_rendering_nothing,
            iou_median = report.iou_quartiles[1],
            rerendered_views,
            seconds = started.elapsed().as_secs_f64(),
            "partial-mask filter"
        );
        self.partial_filter_cost.seconds += started.elapsed().as_secs_f64();
        self.partial_filter_cost.dispatches +=
            segsplat_gpu::dispatches_on_this_thread() - dispatches_before;
        self.skipped_pairs.extend(newly_skipped);
        self.partial_filter_report = Some(report);
        Ok(())
    }

    fn new_encoder(&self, label: &str) -> segsplat_gpu::Encoder {
        segsplat_gpu::Encoder::new(&self.ctx, label)
    }
}

/// Every (object, view) pair, grouped by view (the batches are per view), and each pair's mask
/// pixels.
fn collect_pairs(targets: &ObjectTargets) -> (Vec<SkippedPair>, Vec<u32>) {
    targets
        .views
        .iter()
        .enumerate()
        .flat_map(|(train_view, masks)| {
            Level::ALL.into_iter().flat_map(move |level| {
                let present = &masks.present[level.index()];
                let pixels = &masks.mask_pixels[level.index()];
                present
                    .iter()
                    .zip(pixels)
                    .map(move |(&object_id, &pixels)| {
                        let pair = SkippedPair {
                            train_view,
                            level,
                            object_id,
                        };
                        (pair, pixels)
                    })
            })
        })
        .unzip()
}

/// Object renders per batch for images of `pixels` pixels: as many as fit the share of one
/// storage binding, within [1, PARTIAL_FILTER_MAX_BATCH] (their tile intersections may still
/// need fewer: the filter halves the batch when they pass the adapter's limit).
fn memory_batch_size(ctx: &GpuContext, pixels: usize) -> usize {
    let budget = ctx.limits.max_storage_buffer_binding_size / BATCH_IMAGE_SHARE_OF_BINDING;
    let slot_bytes = (pixels as u64 * 16).max(1);
    ((budget / slot_bytes) as usize).clamp(1, PARTIAL_FILTER_MAX_BATCH)
}
