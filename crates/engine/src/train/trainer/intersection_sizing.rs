//! Fitting the intersection capacity before a trainer's first step.
//!
//! The training loop learns the renders' intersection peak without waiting, a few dozen steps
//! late ([`crate::render::Renderer::request_capacity_check`]); a render over the capacity until
//! then is clamped: it drops tile entries, and its image and gradients are approximate. Later
//! steps grow slowly and the capacity keeps up (a finer resolution grows it ahead, see
//! `Trainer::follow_resolution`), but the first step starts from the renderer's initial guess of
//! 8 intersections a Gaussian: on the figurine at 1000 px the first read, 25 steps in, found all
//! 25 renders clamped, needing 121k entries against 65,536 (`clamped_renders` in a job's
//! metrics.json). So the first step's view is rendered once beforehand and the peak read.

use super::{TrainError, Trainer};
use crate::RenderSettings;
use crate::render::{RENDER_ATTEMPTS, RenderError};

impl Trainer {
    /// Renders training view `view_index` at `divisor` and `time` (forward only, as the coming
    /// step will) and grows the intersection capacity until that render fits; once a trainer,
    /// before its first step (a resumed one too: its checkpoint's capacity is usually enough,
    /// and then this is one render).
    pub(super) fn size_intersections(
        &mut self,
        view_index: usize,
        divisor: u32,
        time: f32,
        settings: &RenderSettings,
    ) -> Result<(), TrainError> {
        // Renders before this one (an evaluation) were used as they were: counted.
        self.renderer.sync_capacity(&self.ctx)?;
        for _ in 0..RENDER_ATTEMPTS {
            let mut encoder = segsplat_gpu::Encoder::new(&self.ctx, "intersection sizing");
            let output =
                self.encode_view_render(&mut encoder, view_index, divisor, time, settings, false)?;
            self.ctx.submit_untimed(encoder.finish());
            drop(output);
            // Rendered only to be measured: a clamped attempt is not a used render.
            if !self.renderer.sync_capacity_to_retry(&self.ctx)?.overflowed {
                self.intersections_sized = true;
                return Ok(());
            }
        }
        Err(RenderError::CapacityNotConverging {
            attempts: RENDER_ATTEMPTS,
        }
        .into())
    }
}
