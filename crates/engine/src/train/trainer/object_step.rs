//! The trainer's Segment-then-Splat extension: the object renders inside each step (see
//! [`crate::train::object_loss`]), batched on the step's full render
//! ([`Renderer::forward_objects`](crate::render::Renderer::forward_objects)). The
//! separate per-object renders they replace stay as the reference (`object_separate.rs`).

use super::{TrainError, Trainer};
use crate::loss::{LossOutputs, ObjectContentHints, ObjectLossImages, ObjectLossSlot};
use crate::render::{ObjectSlot, RenderOutput};
use crate::train::object_loss::{ObjectTargets, SkippedPair, objects_owned, sample_objects};
use crate::train::partial_filter_report::PartialFilterReport;
use segsplat_scene::Level;
use std::collections::BTreeSet;

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
    #[error("training view {view}: object masks are {given} pixels wide, the view is {expected}")]
    Width {
        view: usize,
        given: u32,
        expected: u32,
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
            if masks.width != train_view.camera.width {
                return Err(TrainError::ObjectTargets(ObjectTargetsError::Width {
                    view,
                    given: masks.width,
                    expected: train_view.camera.width,
                }));
            }
            for level in Level::ALL {
                let given = masks.pixel_counts[level.index()];
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
        self.objects_with_gaussians = match &self.config.object_loss {
            Some(config) if config.only_objects_with_gaussians => {
                Some(self.objects_with_gaussians()?)
            }
            _ => None,
        };
        self.object_targets = Some(targets);
        Ok(())
    }

    /// Per level, the object ids the model's Gaussians carry (one read-back of the ids).
    fn objects_with_gaussians(&self) -> Result<[BTreeSet<u32>; 3], TrainError> {
        let count = self.gaussians.count();
        let bytes = self
            .ctx
            .read_buffer(&self.gaussians.object_ids, (count * 3 * 4) as u64)?;
        Ok(objects_owned(bytemuck::cast_slice(&bytes)))
    }

    /// What the partial-mask filter has cost so far.
    pub fn partial_filter_cost(&self) -> super::PartialFilterCost {
        self.partial_filter_cost
    }

    /// What the partial-mask filter found, once it has run.
    pub fn partial_filter_report(&self) -> Option<&PartialFilterReport> {
        self.partial_filter_report.as_ref()
    }

    /// (object, view) pairs the partial-mask filter has left out so far, sorted.
    pub fn skipped_pairs(&self) -> Vec<SkippedPair> {
        self.skipped_pairs.iter().copied().collect()
    }

    /// Renders each step's objects separately (the path before batching: every object
    /// re-projected, re-sorted and back-propagated alone) rather than batched on the step's full
    /// render. Same gradients up to float-atomic order; for tests and benchmarks.
    pub fn set_separate_object_renders(&mut self, separate: bool) {
        self.separate_object_renders = separate;
    }

    /// This step's object slots: for each active level, `m` objects of the view (not skipped
    /// by the partial-mask filter), drawn from the trainer's RNG. None once the loss's weight
    /// is 0 (faded out, or configured so): their renders would train nothing.
    fn sample_object_slots(&mut self, view_index: usize) -> Vec<ObjectSlot> {
        let (Some(config), Some(targets)) = (&self.config.object_loss, &self.object_targets) else {
            return Vec::new();
        };
        if config.weight_at(self.step) == 0.0 {
            return Vec::new();
        }
        let masks = &targets.views[view_index];
        let mut slots = Vec::new();
        for level in config.active_levels(self.step, self.config.steps) {
            let skipped = &self.skipped_pairs;
            let owned = self
                .objects_with_gaussians
                .as_ref()
                .map(|owned| &owned[level.index()]);
            let objects = sample_objects(
                &masks.present[level.index()],
                config.objects_per_level,
                |object_id| {
                    owned.is_some_and(|owned| !owned.contains(&object_id))
                        || skipped.contains(&SkippedPair {
                            train_view: view_index,
                            level,
                            object_id,
                        })
                },
                &mut self.rng,
            );
            slots.extend(objects.into_iter().map(|id| ObjectSlot { level, id }));
        }
        slots
    }

    /// Records the object renders of one step: this step's object slots, each rendered alone on
    /// black with its own loss slot, on top of `base` (the step's full render, whose
    /// screen-space backward is already recorded), their screen-space gradients added to
    /// `base`'s for the step's one projection backward.
    pub(super) fn encode_object_losses(
        &mut self,
        encoder: &mut segsplat_gpu::Encoder,
        view_index: usize,
        sh_degree: u32,
        base: &RenderOutput,
    ) -> Result<(), TrainError> {
        let slots = self.sample_object_slots(view_index);
        if slots.is_empty() {
            return Ok(());
        }
        if self.separate_object_renders {
            return self.encode_separate_object_losses(encoder, view_index, sh_degree, &slots);
        }
        let camera = self.views.train[view_index].camera;
        self.object_buffers
            .reserve(&self.ctx, camera.pixel_count(), slots.len())?;
        let (Some(config), Some(targets)) = (&self.config.object_loss, &self.object_targets) else {
            return Ok(());
        };
        let Some(grad_images) = &self.object_buffers.grad_images else {
            return Ok(());
        };
        let masks = &targets.views[view_index];
        let view = &self.views.train[view_index];
        let scene = super::dynamics::render_view(&self.gaussians, &self.dynamics);
        let batch = self
            .renderer
            .forward_objects(&self.ctx, encoder, scene, base, &slots)?;
        let id_maps: Vec<&wgpu::Buffer> = masks.ids.iter().collect();
        let cell_maps: Vec<&wgpu::Buffer> = masks.cell_maps.iter().collect();
        let loss_slots: Vec<ObjectLossSlot> = slots
            .iter()
            .map(|slot| ObjectLossSlot {
                id_map: slot.level.index() as u32,
                object_id: slot.id,
            })
            .collect();
        self.loss.encode_objects(
            &self.ctx,
            encoder,
            &ObjectLossImages {
                rendered: batch.images(),
                rendered_index: 0,
                target: &view.target,
                id_maps: &id_maps,
                slots: &loss_slots,
                width: camera.width,
                height: camera.height,
                content: Some(ObjectContentHints {
                    occupancy: batch.occupancy(),
                    cell_maps: &cell_maps,
                }),
            },
            config.weight_at(self.step),
            &LossOutputs {
                rendered_grad: grad_images,
                grad_index: 0,
                loss_values: &self.loss_values,
                loss_slot: 1,
            },
        )?;
        self.renderer
            .backward_objects_screen(&self.ctx, encoder, &batch, grad_images)?;
        Ok(())
    }
}

/// The step's object loss gradients, grown on demand (a trainer without the object loss never
/// allocates them).
#[derive(Debug, Default)]
pub(super) struct ObjectBuffers {
    /// Every slot's d loss / d image, slot after slot, as the batched backward reads them.
    grad_images: Option<wgpu::Buffer>,
}

impl ObjectBuffers {
    fn reserve(
        &mut self,
        ctx: &segsplat_gpu::GpuContext,
        pixels: usize,
        slots: usize,
    ) -> Result<(), segsplat_gpu::GpuError> {
        let bytes = pixels as u64 * 16 * slots as u64;
        if self.grad_images.as_ref().is_some_and(|b| b.size() >= bytes) {
            return Ok(());
        }
        self.grad_images = Some(ctx.storage_buffer("object grad images", bytes)?);
        Ok(())
    }
}
