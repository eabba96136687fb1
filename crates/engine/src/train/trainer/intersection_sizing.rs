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
//!
//! In the steps after it the model's footprints grow fastest (opacities and scales leave their
//! initial values, and a footprint is where alpha reaches its threshold, so it widens with the
//! opacity): with the peak read every 25 steps, a figurine job at 1000 px still counted one
//! clamped render, read at step 75, a view needing more than 1.5x the peak read at step 50. So
//! for the first [`WATCHED_STEPS`] every step also copies its peak for a read without waiting,
//! and the next step grows the capacity for the newest peak delivered: eight bytes a step.

use super::{TrainError, Trainer};
use crate::RenderSettings;
use crate::render::{RENDER_ATTEMPTS, RenderError};

/// The first steps of a run whose renders' peak is read every step (see the module's notes).
pub(super) const WATCHED_STEPS: u32 = 100;

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
        // Rendered only to be measured: a clamped attempt is not a used render.
        self.until_renders_fit(|trainer| {
            let mut encoder = segsplat_gpu::Encoder::new(&trainer.ctx, "intersection sizing");
            let output = trainer.encode_view_render(
                &mut encoder,
                view_index,
                divisor,
                time,
                settings,
                false,
            )?;
            trainer.ctx.submit_untimed(encoder.finish());
            drop(output);
            Ok(())
        })?;
        self.intersections_sized = true;
        Ok(())
    }

    /// Runs `attempt`, whose renders train nothing (they are measured or timed), until none of
    /// them was clamped, growing the capacity for their peak in between; the clamped attempts
    /// are not counted as used renders, while renders before the first were used as they were
    /// and are counted. Returns the last attempt's value.
    pub(super) fn until_renders_fit<T>(
        &mut self,
        mut attempt: impl FnMut(&mut Self) -> Result<T, TrainError>,
    ) -> Result<T, TrainError> {
        self.renderer.sync_capacity(&self.ctx)?;
        for _ in 0..RENDER_ATTEMPTS {
            let value = attempt(self)?;
            if !self.renderer.sync_capacity_to_retry(&self.ctx)?.overflowed {
                return Ok(value);
            }
        }
        Err(RenderError::CapacityNotConverging {
            attempts: RENDER_ATTEMPTS,
        }
        .into())
    }

    /// Before a watched step ([`WATCHED_STEPS`]): grows the capacity for the newest peak a
    /// watched step has delivered, without waiting, and counts the renders it found clamped.
    pub(super) fn apply_watched_peak(&mut self, step: u32) -> Result<(), TrainError> {
        if step > WATCHED_STEPS {
            return Ok(());
        }
        self.apply_deferred_peak()
    }

    /// Grows the capacity for the newest peak the device has delivered, without waiting, and
    /// logs the clamped renders it reports.
    pub(super) fn apply_deferred_peak(&mut self) -> Result<(), TrainError> {
        let clamped_before = self.renderer.clamped_renders();
        self.renderer.apply_capacity_check(&self.ctx)?;
        self.log_clamped_since(clamped_before);
        Ok(())
    }

    /// Records, at the end of watched step `step`'s `encoder`, a copy of its peak; the caller
    /// passes what this returns to [`Self::watched_peak_submitted`] after submitting.
    pub(super) fn request_watched_peak(
        &mut self,
        encoder: &mut segsplat_gpu::Encoder,
        step: u32,
    ) -> Option<usize> {
        if step > WATCHED_STEPS {
            return None;
        }
        self.renderer.request_capacity_check(encoder)
    }

    /// See [`Self::request_watched_peak`].
    pub(super) fn watched_peak_submitted(&mut self, slot: Option<usize>) {
        if let Some(slot) = slot {
            self.renderer.capacity_check_submitted(slot);
        }
    }
}
