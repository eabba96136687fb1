//! The convergence stop's check ([`crate::train::convergence`]): a few training views rendered
//! at full resolution every few passes once the schedule has finished changing the model's
//! shape, and the run ended when their PSNR stops gaining.

use super::{TrainError, Trainer};
use crate::train::convergence::{ConvergenceTracker, Verdict, check_view_indices};

/// The convergence stop of one trainer: the tracker (made at the first check, when the object
/// loss, which moves the floor, has been attached), the check views' images and the verdict.
#[derive(Default)]
pub(super) struct FitCheck {
    tracker: Option<ConvergenceTracker>,
    /// (training view index, its image as RGB), read back once.
    targets: Vec<(usize, Vec<[f32; 3]>)>,
    converged: Option<ConvergedAt>,
}

/// Where and why a run stopped before its steps.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConvergedAt {
    /// The step the run ends at.
    pub step: u32,
    /// The check that found the fit no longer gaining.
    pub verdict_step: u32,
    /// What the check views gained over the rule's window (below its minimum).
    pub gain_db: f64,
    /// The check views' mean PSNR at the verdict.
    pub fit_psnr: f64,
    /// When the verdict came before the object loss's partial-mask filter: the step the filter
    /// runs after instead (the one after the verdict), the run then training a check interval
    /// more on the filtered pairs before it ends. The filter is part of the method: an early
    /// end must not skip it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub partial_filter_step: Option<u32>,
}

impl FitCheck {
    /// A resumed run's verdict, from its checkpoint.
    pub(super) fn restore(&mut self, converged: Option<ConvergedAt>) {
        self.converged = converged;
    }
}

impl Trainer {
    /// The step the run ends at: its configured steps, or the step its convergence stop ended
    /// it at.
    pub fn end_step(&self) -> u32 {
        self.fit_check
            .converged
            .map_or(self.config.steps, |at| at.step)
    }

    /// Where the convergence stop ended the run, if it did.
    pub fn converged_at(&self) -> Option<ConvergedAt> {
        self.fit_check.converged
    }

    /// The step the partial-mask filter runs after: its share of the laid-out steps (the
    /// configured steps unless `schedule_steps` is shorter), or earlier when the convergence
    /// stop's verdict came first.
    pub(super) fn partial_filter_step(&self) -> Option<u32> {
        let configured = self
            .config
            .object_loss
            .as_ref()
            .map(|objects| objects.partial_filter_step(self.schedule.laid_out_over))?;
        Some(
            self.fit_check
                .converged
                .and_then(|at| at.partial_filter_step)
                .unwrap_or(configured),
        )
    }

    /// Every convergence check so far: (step, mean PSNR of the check views).
    pub fn fit_checks(&self) -> &[(u32, f64)] {
        self.fit_check
            .tracker
            .as_ref()
            .map_or(&[], ConvergenceTracker::history)
    }

    /// The first step a convergence check may run at: after densification, the coarse steps,
    /// the last SH band, the object levels joining, and the deformation field's warm-up (a
    /// check before them would compare a model still changing shape). The partial-mask filter
    /// is not waited for: a verdict before it brings it forward.
    pub fn convergence_floor(&self) -> u32 {
        let schedule = &self.schedule;
        let steps = self.config.steps;
        let densify_end = if schedule.densify_until > schedule.densify_from {
            schedule
                .densify_until
                .min(steps.saturating_sub(schedule.settle_margin))
        } else {
            0
        };
        let last_band = schedule
            .sh_degree_interval
            .saturating_mul(schedule.max_sh_degree);
        let levels = self.config.object_loss.as_ref().map_or(0, |objects| {
            (objects.large_from * steps as f32).ceil() as u32
        });
        let warm_up = schedule.deformation.map_or(0, |d| d.warm_up_steps);
        [
            densify_end,
            schedule.coarse_until,
            last_band,
            levels,
            warm_up,
        ]
        .into_iter()
        .max()
        .unwrap_or(0)
        .min(steps)
    }

    /// After `step` (just finished): runs the convergence check when one is due and ends the
    /// run when it says so. Returns whether the run has ended.
    pub(super) fn check_convergence(&mut self, step: u32) -> Result<bool, TrainError> {
        let Some(rule) = self.config.stop_when_converged else {
            return Ok(false);
        };
        if let Some(converged) = self.fit_check.converged {
            return Ok(step >= converged.step);
        }
        if self.fit_check.tracker.is_none() {
            let floor = self.convergence_floor();
            self.fit_check.tracker =
                Some(ConvergenceTracker::new(rule, self.views.train.len(), floor));
        }
        let due = self
            .fit_check
            .tracker
            .as_ref()
            .is_some_and(|tracker| tracker.due_at(step));
        if !due || step >= self.config.steps {
            return Ok(false);
        }
        let fit_psnr = self.check_views_psnr(rule.check_views)?;
        let verdict = match self.fit_check.tracker.as_mut() {
            Some(tracker) => tracker.observe(step, fit_psnr),
            None => Verdict::GoOn,
        };
        let Verdict::Converged { gain_db } = verdict else {
            return Ok(false);
        };
        // The filter has not run yet: it runs after the next step, and the run trains a
        // check interval on the filtered pairs before it ends.
        let filter_pending =
            self.object_targets.is_some() && self.partial_filter_step().is_some_and(|at| at > step);
        let settle = rule
            .check_every_passes
            .saturating_mul(self.views.train.len() as u32);
        let converged = ConvergedAt {
            step: if filter_pending {
                step.saturating_add(1).saturating_add(settle)
            } else {
                step
            }
            .min(self.config.steps),
            verdict_step: step,
            gain_db,
            fit_psnr,
            partial_filter_step: filter_pending.then_some(step + 1),
        };
        self.fit_check.converged = Some(converged);
        Ok(step >= converged.step)
    }

    /// The mean PSNR of the check views rendered at full resolution (their images read back
    /// at the first check).
    fn check_views_psnr(&mut self, count: u32) -> Result<f64, TrainError> {
        if self.fit_check.targets.is_empty() {
            for index in check_view_indices(self.views.train.len(), count) {
                let rgba: Vec<[f32; 4]> = self.ctx.read_vec(&self.views.train[index].target)?;
                let pixels = self.views.train[index].camera.pixel_count();
                let rgb = rgba
                    .iter()
                    .take(pixels)
                    .map(|p| [p[0], p[1], p[2]])
                    .collect();
                self.fit_check.targets.push((index, rgb));
            }
        }
        // By position, not by iterator: rendering needs `&mut self`, the targets stay in place.
        let count = self.fit_check.targets.len();
        let mut total = 0.0;
        for slot in 0..count {
            let index = self.fit_check.targets[slot].0;
            let rendered = self.rendered_rgb(false, index)?;
            total += crate::image_metrics::psnr(&rendered, &self.fit_check.targets[slot].1);
        }
        Ok(total / count.max(1) as f64)
    }
}
