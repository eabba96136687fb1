//! Measuring the trainer without changing the model: the step's render passes timed, and the
//! held-out views evaluated.

use std::time::Instant;

use super::{EvalReport, TrainError, Trainer, dynamics};
use crate::{ObjectFilter, RenderSettings};

impl Trainer {
    /// Times a step's render passes ([`Self::encode_view_render`]) on the training views without
    /// changing the model: forward alone, and forward + loss + backward, each submitted and
    /// waited for (wall clock, so it includes submission overhead). A dynamic scene's views are
    /// rendered through the deformation at their own time (no time noise, which would draw from
    /// the training's random numbers); the field's own backward is not timed. Returns (forward ms, backward-with-loss ms) averaged over `repeats`,
    /// after one untimed round (the first render of a trainer pays first-use costs, such as
    /// growing the intersection buffers, which would otherwise land in the forward figure).
    ///
    /// The timed renders run at full resolution, where a trainer's capacity may not have been
    /// fitted yet (bench times them before the first step): a round with a clamped render is
    /// timed again at the capacity its peak grew, since a clamped render skips work and times
    /// short. Those renders train nothing, so they are not counted as clamped renders used.
    pub fn time_passes(&mut self, repeats: u32) -> Result<(f64, f64), TrainError> {
        self.until_renders_fit(|trainer| trainer.time_passes_once(repeats))
    }

    fn time_passes_once(&mut self, repeats: u32) -> Result<(f64, f64), TrainError> {
        let settings = RenderSettings {
            filter: ObjectFilter::All,
            background: self.config.background,
            sh_degree: self.schedule.sh_degree_at(self.step),
        };
        let ctx = self.ctx.clone();
        let (mut forward_secs, mut full_secs) = (0.0, 0.0);
        for repeat in 0..=repeats.max(1) {
            let view_index = repeat as usize % self.views.train.len();
            let time = self.views.train[view_index].time;
            for with_backward in [false, true] {
                let started = Instant::now();
                let mut encoder = segsplat_gpu::Encoder::new(&ctx, "timing");
                if with_backward {
                    self.grads.encode_zero(&mut encoder);
                }
                let output = self.encode_view_render(
                    &mut encoder,
                    view_index,
                    1,
                    time,
                    &settings,
                    with_backward,
                )?;
                if with_backward {
                    self.encode_projection_backward(&mut encoder, &output)?;
                }
                ctx.submit_untimed(encoder.finish());
                ctx.wait_idle()?;
                let secs = started.elapsed().as_secs_f64();
                if repeat == 0 {
                    continue;
                } else if with_backward {
                    full_secs += secs;
                } else {
                    forward_secs += secs;
                }
            }
        }
        let repeats = repeats.max(1) as f64;
        let forward_ms = forward_secs / repeats * 1e3;
        let full_ms = full_secs / repeats * 1e3;
        Ok((forward_ms, (full_ms - forward_ms).max(0.0)))
    }

    /// Renders every held-out view and compares it with its image.
    pub fn evaluate(&mut self) -> Result<EvalReport, TrainError> {
        let mut report = EvalReport::default();
        for index in 0..self.views.test.len() {
            let rendered = self.rendered_rgb(true, index)?;
            let view = &self.views.test[index];
            let psnr = crate::image_metrics::psnr(&rendered, &view.target_rgb);
            if report.views == 0 || psnr < report.worst_psnr {
                report.worst_psnr = psnr;
                report.worst_view = report.views;
                report.worst_frame_index = Some(view.frame_index);
                report.worst_frame_name = Some(view.name.clone());
            }
            report.psnr += psnr;
            report.ssim += crate::image_metrics::ssim(
                &rendered,
                &view.target_rgb,
                view.camera.width as usize,
                view.camera.height as usize,
            );
            report.views += 1;
        }
        if report.views > 0 {
            report.psnr /= report.views as f64;
            report.ssim /= report.views as f64;
        }
        Ok(report)
    }

    /// A held-out (`held_out`) or training view rendered at full resolution (at its own time in
    /// a dynamic scene), clamped to 0..1 RGB, row-major.
    pub(super) fn rendered_rgb(
        &mut self,
        held_out: bool,
        index: usize,
    ) -> Result<Vec<[f32; 3]>, TrainError> {
        let settings = RenderSettings {
            filter: ObjectFilter::All,
            background: self.config.background,
            sh_degree: self.schedule.sh_degree_at(self.step),
        };
        let view = if held_out {
            &self.views.test[index]
        } else {
            &self.views.train[index]
        };
        if self.dynamics.is_some() {
            let mut encoder = segsplat_gpu::Encoder::new(&self.ctx, "deform for evaluation");
            dynamics::deform_to(
                &self.ctx,
                self.step,
                &mut self.dynamics,
                &self.gaussians,
                &mut encoder,
                view.time,
            )?;
            self.ctx.submit_untimed(encoder.finish());
        }
        let output = self.renderer.render_checked(
            &self.ctx,
            dynamics::render_view(&self.gaussians, &self.dynamics),
            &view.camera,
            &settings,
        )?;
        let image = output.read_image(&self.ctx)?;
        Ok(image
            .iter()
            .take(view.camera.pixel_count())
            .map(|p| {
                [
                    p[0].clamp(0.0, 1.0),
                    p[1].clamp(0.0, 1.0),
                    p[2].clamp(0.0, 1.0),
                ]
            })
            .collect())
    }
}
