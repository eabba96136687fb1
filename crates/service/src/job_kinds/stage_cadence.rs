//! When a job's training stage stops between steps: for a checkpoint every `checkpoint_every`
//! steps and for a held-out evaluation every `held_out_every` (a job config's keys), and what
//! each evaluation leaves in metrics.json.

use serde::{Deserialize, Serialize};

/// Held-out quality after `step` steps (`training.held_out_curve` in metrics.json).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HeldOutPoint {
    pub step: u32,
    /// The stage's wall seconds so far, less its checkpoints, reports and evaluations.
    pub train_seconds: f64,
    pub gaussians: usize,
    pub psnr: f64,
    pub ssim: f64,
}

/// How often the training stage stops for a checkpoint and for a held-out evaluation, in steps
/// (0: a checkpoint only at the end; no evaluations before the job's own at the end).
#[derive(Debug, Clone, Copy, Default)]
pub struct StageCadence {
    pub checkpoint_every: u32,
    pub held_out_every: u32,
}

impl StageCadence {
    /// The step after `step` at which a checkpoint is due (`total`: the last).
    pub(crate) fn next_checkpoint(&self, step: u32, total: u32) -> u32 {
        next_multiple(step, self.checkpoint_every, total)
    }

    /// The step after `step` at which a held-out evaluation is due (`total` when none is).
    pub(crate) fn next_held_out(&self, step: u32, total: u32) -> u32 {
        next_multiple(step, self.held_out_every, total)
    }
}

/// The next multiple of `every` after `step`, at most `total` (`total` for 0).
fn next_multiple(step: u32, every: u32, total: u32) -> u32 {
    match every {
        0 => total,
        every => (step / every + 1).saturating_mul(every).min(total),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stage_stops_at_each_checkpoint_and_evaluation_and_at_its_end() {
        let cadence = StageCadence {
            checkpoint_every: 25,
            held_out_every: 20,
        };
        assert_eq!(cadence.next_checkpoint(0, 60), 25);
        assert_eq!(cadence.next_held_out(0, 60), 20);
        assert_eq!(cadence.next_held_out(20, 60), 40);
        assert_eq!(cadence.next_checkpoint(50, 60), 60);
        assert_eq!(cadence.next_held_out(40, 60), 60);
        // A resumed attempt goes on from its checkpoint's step.
        assert_eq!(cadence.next_held_out(25, 60), 40);
        let at_the_end = StageCadence::default();
        assert_eq!(at_the_end.next_checkpoint(10, 60), 60);
        assert_eq!(at_the_end.next_held_out(10, 60), 60);
        assert_eq!(next_multiple(u32::MAX - 1, 1 << 31, u32::MAX), u32::MAX);
    }
}
