//! What the training job kinds share: failure classification, progress reports, checkpointed
//! training that honours cancel and shutdown at step boundaries.

use std::sync::Arc;

use super::stop_aware::StopSignal;
use crate::jobs::{JobContext, JobFailure, Progress};
use crate::store::BlobError;
use segsplat_engine::GaussianModel;
use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::model::ModelError;
use segsplat_engine::train::{EvalReport, TrainError, TrainProgress, Trainer, TrainerMeta};
use segsplat_gpu::HostCostReading;
use segsplat_method::cameras::CAMERAS_FILE;
use segsplat_method::scene_files::write_scene_files;
use segsplat_method::scene_files::{LABELS_FILE, SCENE_FILE};
use segsplat_scene::Scene;
use serde::{Deserialize, Serialize};

pub fn fatal(error: impl std::fmt::Display) -> JobFailure {
    JobFailure::Fatal(error.to_string())
}

pub fn retryable(error: impl std::fmt::Display) -> JobFailure {
    JobFailure::Retryable(error.to_string())
}

/// Bad config or data cannot succeed on retry; GPU and I/O trouble might.
pub fn train_failure(error: TrainError) -> JobFailure {
    match error {
        // A retry would fail the same way: the config or the data, not the moment, is wrong.
        TrainError::Config(_)
        | TrainError::Views(_)
        | TrainError::EmptyModel
        | TrainError::ObjectTargets(_)
        | TrainError::Model(ModelError::TooLargeForAdapter { .. }) => fatal(error),
        other => retryable(other),
    }
}

/// Reports one stage's progress; a failed report is logged, never fatal.
pub fn report(ctx: &JobContext, stage: &str, step: u64, total_steps: u64, metrics: &[(&str, f64)]) {
    let progress = Progress {
        stage: stage.to_string(),
        step,
        total_steps,
        metrics: metrics
            .iter()
            .map(|(name, value)| (name.to_string(), *value))
            .collect(),
        eta_secs: None,
    };
    if let Err(error) = ctx.progress.report_blocking(progress) {
        tracing::warn!(%error, "progress report failed");
    }
}

/// Records a `warning` job event for every stage the trainer's config makes impossible (a
/// deformation warm-up longer than the job, densification that never starts, ...), and logs it.
pub fn warn_about_schedule(ctx: &JobContext, trainer: &Trainer) {
    for message in trainer.schedule().warnings() {
        tracing::warn!(job = %ctx.job_id, "{message}");
        if let Err(error) = ctx.progress.warn_blocking("train", &message) {
            tracing::warn!(%error, "warning event not recorded");
        }
    }
}

fn report_training(ctx: &JobContext, progress: &TrainProgress) {
    let mut metrics = vec![
        ("loss", progress.loss as f64),
        ("gaussians", progress.gaussians as f64),
        ("steps_per_sec", progress.steps_per_sec),
    ];
    if progress.object_loss != 0.0 {
        metrics.push(("object_loss", progress.object_loss as f64));
    }
    report(
        ctx,
        "train",
        progress.step as u64,
        progress.total_steps as u64,
        &metrics,
    );
}

/// The newest trainer checkpoint this job saved that still decodes, recorded as a `resumed`
/// event; `None` when the job starts from the beginning.
pub fn load_resume_point(
    ctx: &JobContext,
    name: &str,
) -> Result<Option<Checkpoint<TrainerMeta>>, JobFailure> {
    let checkpoint = ctx
        .load_checkpoint(name, |bytes| {
            Checkpoint::<TrainerMeta>::from_bytes(bytes).map_err(|error| error.to_string())
        })
        .map_err(JobFailure::from)?;
    if let Some(checkpoint) = &checkpoint {
        tracing::info!(step = checkpoint.meta.step, "resuming from checkpoint");
        if let Err(error) = ctx
            .progress
            .resumed_blocking("train", u64::from(checkpoint.meta.step))
        {
            tracing::warn!(%error, "cannot record the resume");
        }
    }
    Ok(checkpoint)
}

/// Saves the trainer's checkpoint. While the blob store is unreachable the checkpoint waits:
/// training goes on with a `warning` job event, and the next checkpoint tries again (a crash
/// meanwhile costs the steps since the last saved one, as always).
fn save_checkpoint(ctx: &JobContext, name: &str, trainer: &Trainer) -> Result<(), JobFailure> {
    let bytes = trainer
        .checkpoint()
        .and_then(|c| Ok(c.to_bytes()?))
        .map_err(train_failure)?;
    match ctx.save_checkpoint(name, &bytes) {
        Err(error @ BlobError::Unavailable { .. }) => {
            let message = format!(
                "{error}; checkpoint at step {} skipped, training goes on",
                trainer.step()
            );
            tracing::warn!(job = %ctx.job_id, "{message}");
            ctx.progress.warn_detached("train", &message);
            Ok(())
        }
        other => other.map_err(JobFailure::from),
    }
}

/// How this attempt's training stage went (`training` in a job's metrics.json): its time, and
/// per step what the host did besides waiting for the GPU, so a job's overhead over the
/// engine's own step can be read without a GPU (docs/benchmarks.md, "The host's side").
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TrainingStageReport {
    /// Wall seconds of the stage, checkpoints included.
    pub seconds: f64,
    /// Steps trained in this attempt (a resumed attempt starts at its checkpoint).
    pub steps: u32,
    /// Gaussians densification could grow to (the config's, or the scene's).
    pub gaussian_budget: usize,
    /// Wall seconds spent writing checkpoints (inside `seconds`).
    pub checkpoint_seconds: f64,
    /// Wall seconds spent reporting progress (inside `seconds`).
    #[serde(default)]
    pub report_seconds: f64,
    /// `seconds` over the seconds of the steps themselves (the stage less its checkpoints and
    /// progress reports): the job's step rate against `segsplat bench`'s loop on the same
    /// models. 1.0 is no overhead.
    #[serde(default)]
    pub job_overhead_ratio: f64,
    pub dispatches_per_step: f64,
    pub bytes_read_back_per_step: f64,
    /// Host milliseconds a step outside the device's work and checkpoints (encoding,
    /// progress, densification's re-layout on the CPU).
    pub host_ms_per_step: f64,
    /// Milliseconds a step the host waited for the GPU (read-backs, waits).
    pub wait_ms_per_step: f64,
    /// Milliseconds a step inside queue submissions (a software adapter runs the work there).
    #[serde(default)]
    pub submit_ms_per_step: f64,
}

/// Trains to the configured end, saving a checkpoint named `checkpoint_name` every
/// `checkpoint_every` steps (0 = only at the end) and stopping at the next report when the job
/// is cancelled or the service shuts down. Returns how this attempt's training went.
pub fn train_with_checkpoints(
    ctx: &JobContext,
    trainer: &mut Trainer,
    checkpoint_name: &str,
    checkpoint_every: u32,
) -> Result<TrainingStageReport, JobFailure> {
    let total = trainer.config().steps;
    if trainer.step() == 0 {
        warn_about_schedule(ctx, trainer);
    }
    let gpu = trainer.gpu().clone();
    let first_step = trainer.step();
    let dispatches_before = gpu.dispatch_count();
    let host_before = gpu.host_costs.reading();
    let started = std::time::Instant::now();
    let mut checkpoint_seconds = 0.0;
    let mut report_seconds = 0.0;
    let mut checkpoint_host = HostCostReading::default();
    // Heard inside a step's long passes (the partial-mask filter), not only between reports.
    let stop = StopSignal::of(ctx);
    trainer.set_stop_check(Arc::new(move || stop.requested()));
    while trainer.step() < total {
        let next_checkpoint = match checkpoint_every {
            0 => total,
            every => (trainer.step() / every + 1) * every,
        };
        trainer
            .run_until(next_checkpoint, |progress| {
                let reporting = std::time::Instant::now();
                report_training(ctx, progress);
                let go_on = ctx.stop_requested().is_ok();
                report_seconds += reporting.elapsed().as_secs_f64();
                go_on
            })
            .map_err(|error| {
                match error {
                    // The stop's own failure (cancelled, or handed back at shutdown).
                    TrainError::Stopped { .. } => ctx.stop_requested().err(),
                    _ => None,
                }
                .unwrap_or_else(|| train_failure(error))
            })?;
        ctx.stop_requested()?;
        let checkpoint_started = std::time::Instant::now();
        let host_at_checkpoint = gpu.host_costs.reading();
        save_checkpoint(ctx, checkpoint_name, trainer)?;
        checkpoint_seconds += checkpoint_started.elapsed().as_secs_f64();
        checkpoint_host.add(&gpu.host_costs.reading().since(&host_at_checkpoint));
    }
    let seconds = started.elapsed().as_secs_f64();
    let host = gpu.host_costs.reading().since(&host_before);
    let steps = trainer.step() - first_step;
    let per_step = |value: f64| value / f64::from(steps.max(1));
    let waited = host.wait_seconds() - checkpoint_host.wait_seconds();
    let submitted = host.submit_seconds() - checkpoint_host.submit_seconds();
    Ok(TrainingStageReport {
        seconds,
        steps,
        gaussian_budget: trainer.gaussian_budget(),
        checkpoint_seconds,
        report_seconds,
        job_overhead_ratio: seconds / (seconds - checkpoint_seconds - report_seconds).max(1e-9),
        dispatches_per_step: per_step((gpu.dispatch_count() - dispatches_before) as f64),
        bytes_read_back_per_step: per_step(
            (host.bytes_read_back - checkpoint_host.bytes_read_back) as f64,
        ),
        host_ms_per_step: per_step(
            (seconds - checkpoint_seconds - waited - submitted).max(0.0) * 1e3,
        ),
        wait_ms_per_step: per_step(waited.max(0.0) * 1e3),
        submit_ms_per_step: per_step(submitted.max(0.0) * 1e3),
    })
}

/// Stores a finished job's outputs under its output prefix: the trained scene (`scene.ply`,
/// Inria layout, `labels.npy`, object ids in PLY order, and `cameras.json`) and the given JSON
/// documents.
pub fn store_outputs(
    ctx: &JobContext,
    model: &GaussianModel,
    scene: &Scene,
    documents: &[(&str, Vec<u8>)],
) -> Result<(), JobFailure> {
    write_scene_files(model, scene, &ctx.work_dir).map_err(retryable)?;
    let prefix = ctx.output_prefix();
    // The training is done: an outage of the store is waited out rather than losing it.
    for file in [SCENE_FILE, LABELS_FILE, CAMERAS_FILE] {
        let key = format!("{prefix}/{file}");
        ctx.while_blobs_unavailable(&format!("storing {key}"), || {
            ctx.blobs.put_file(&key, &ctx.work_dir.join(file))
        })?;
    }
    for (file, bytes) in documents {
        let key = format!("{prefix}/{file}");
        ctx.while_blobs_unavailable(&format!("storing {key}"), || {
            ctx.blobs.put_bytes(&key, bytes)
        })?;
    }
    Ok(())
}

/// Reports the held-out evaluation as the "evaluate" stage.
pub fn report_evaluation(ctx: &JobContext, held_out: &EvalReport, gaussians: usize) {
    report(
        ctx,
        "evaluate",
        1,
        1,
        &[
            ("psnr", held_out.psnr),
            ("ssim", held_out.ssim),
            ("worst_psnr", held_out.worst_psnr),
            ("gaussians", gaussians as f64),
        ],
    );
}
