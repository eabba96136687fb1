//! `bench --eval-every N`: held-out quality against training time, for comparing schedules by
//! what a user waits for rather than by steps.

use segsplat_engine::train::Trainer;
use segsplat_gpu::GpuContext;
use serde::Serialize;

use super::TimedRun;

/// Held-out quality after `step` steps, `train_seconds` of training in.
#[derive(Debug, Clone, Serialize)]
pub struct CurvePoint {
    pub step: u32,
    /// Training time so far (evaluations excluded).
    pub train_seconds: f64,
    pub gaussians: usize,
    pub psnr: f64,
    pub ssim: f64,
}

/// Trains `trainer` to its last step, evaluating the held-out views every `every` steps and at
/// the end; only the training counts towards the times.
pub fn run_with_curve(
    ctx: &GpuContext,
    trainer: &mut Trainer,
    every: u32,
) -> anyhow::Result<(TimedRun, Vec<CurvePoint>)> {
    let every = every.max(1);
    let mut run = TimedRun::default();
    let mut dispatches = 0u64;
    let mut curve = Vec::new();
    while trainer.step() < trainer.end_step() {
        let last_step = trainer.step().saturating_add(every);
        dispatches += run.train_turn(ctx, trainer, last_step)?;
        let eval = trainer.evaluate()?;
        curve.push(CurvePoint {
            step: trainer.step(),
            train_seconds: run.seconds,
            gaussians: trainer.gaussian_count(),
            psnr: eval.psnr,
            ssim: eval.ssim,
        });
    }
    run.dispatches_per_step = dispatches as f64 / f64::from(run.steps.max(1));
    Ok((run, curve))
}
