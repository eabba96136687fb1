//! The object renders of a step recorded separately, one full render pipeline per object (the
//! path before batching). Kept as the reference the batched path must match
//! ([`Trainer::set_separate_object_renders`]) and for benchmarks.

use super::{TrainError, Trainer};
use crate::RenderSettings;
use crate::loss::{LossImages, LossOutputs, ObjectMask};
use crate::render::ObjectSlot;

impl Trainer {
    /// Each slot re-projected, re-sorted, rasterized, its loss, and its whole backward.
    pub(super) fn encode_separate_object_losses(
        &mut self,
        encoder: &mut segsplat_gpu::Encoder,
        view_index: usize,
        sh_degree: u32,
        slots: &[ObjectSlot],
    ) -> Result<(), TrainError> {
        let (Some(config), Some(targets)) = (&self.config.object_loss, &self.object_targets) else {
            return Ok(());
        };
        let masks = &targets.views[view_index];
        let view = &self.views.train[view_index];
        for (index, slot) in slots.iter().enumerate() {
            let settings = RenderSettings {
                filter: slot.filter(),
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
                    rendered_index: 0,
                    target: &view.target,
                    target_mask: Some(ObjectMask {
                        object_ids: &masks.ids[slot.level.index()],
                        object_id: slot.id,
                    }),
                    width: view.camera.width,
                    height: view.camera.height,
                },
                config.weight_at(self.step),
                &LossOutputs {
                    rendered_grad: &self.grad_image,
                    grad_index: 0,
                    loss_values: &self.loss_values,
                    loss_slot: 1 + index as u32,
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
        }
        Ok(())
    }
}
