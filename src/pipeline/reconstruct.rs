//! The `reconstruct` job: plain 3DGS on an uploaded scene. Resumes from its last checkpoint
//! (saved every `checkpoint_every` steps to the blob store), reports progress at every sync point,
//! honours cancel at those step boundaries, and leaves `scene.ply` (Inria layout), `labels.npy`
//! and `metrics.json` under the job's output prefix.

use std::sync::Arc;

use futures::future::BoxFuture;
use serde::{Deserialize, Serialize};

use crate::gpu::GpuContext;
use crate::jobs::{JobContext, JobFailure, JobHandler, Progress};
use crate::scene::{LoadOptions, load_scene};
use crate::splat::checkpoint::Checkpoint;
use crate::splat::labels::write_labels;
use crate::splat::model::GaussianModel;
use crate::splat::ply::write_ply;
use crate::splat::train::{
    EvalReport, TrainConfig, TrainError, TrainProgress, Trainer, TrainerMeta,
};

pub const KIND: &str = "reconstruct";
const CHECKPOINT_NAME: &str = "train";

/// The job's config: training settings plus how often to checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReconstructConfig {
    #[serde(flatten)]
    pub train: TrainConfig,
    /// Steps between checkpoints (0 = only at the end).
    pub checkpoint_every: u32,
}

impl Default for ReconstructConfig {
    fn default() -> Self {
        Self {
            train: TrainConfig::default(),
            checkpoint_every: 1000,
        }
    }
}

/// What a finished reconstruction reports.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReconstructMetrics {
    pub steps: u32,
    pub gaussians: usize,
    /// Wall time of this attempt's training (resumed attempts count only their own part).
    pub train_seconds: f64,
    pub held_out: EvalReport,
}

/// Writes `scene.ply` and `labels.npy` (object ids in PLY order) into `dir`.
pub fn write_scene_files(model: &GaussianModel, dir: &std::path::Path) -> std::io::Result<()> {
    let to_io = |error: &dyn std::fmt::Display| std::io::Error::other(error.to_string());
    let ply = std::fs::File::create(dir.join("scene.ply"))?;
    write_ply(model, ply).map_err(|e| to_io(&e))?;
    let labels = std::fs::File::create(dir.join("labels.npy"))?;
    write_labels(&model.object_ids, labels).map_err(|e| to_io(&e))?;
    Ok(())
}

#[derive(Debug, Default)]
pub struct ReconstructHandler;

impl JobHandler for ReconstructHandler {
    fn kind(&self) -> &'static str {
        KIND
    }

    fn validate_config(&self, config: &serde_json::Value) -> Result<serde_json::Value, String> {
        let parsed: ReconstructConfig = if config.is_null() {
            ReconstructConfig::default()
        } else {
            serde_json::from_value(config.clone()).map_err(|error| error.to_string())?
        };
        parsed.train.validate().map_err(|error| error.to_string())?;
        serde_json::to_value(&parsed).map_err(|error| error.to_string())
    }

    fn run(&self, ctx: JobContext) -> BoxFuture<'static, Result<(), JobFailure>> {
        Box::pin(async move {
            let ctx = Arc::new(ctx);
            let worker = Arc::clone(&ctx);
            tokio::task::spawn_blocking(move || run_blocking(&worker))
                .await
                .map_err(|error| JobFailure::Retryable(format!("worker thread failed: {error}")))?
        })
    }
}

fn fatal(error: impl std::fmt::Display) -> JobFailure {
    JobFailure::Fatal(error.to_string())
}

fn retryable(error: impl std::fmt::Display) -> JobFailure {
    JobFailure::Retryable(error.to_string())
}

fn train_failure(error: TrainError) -> JobFailure {
    match error {
        TrainError::Config(_) | TrainError::Views(_) | TrainError::EmptyModel => fatal(error),
        other => retryable(other),
    }
}

fn run_blocking(ctx: &JobContext) -> Result<(), JobFailure> {
    let config: ReconstructConfig = serde_json::from_value(ctx.config.clone()).map_err(fatal)?;
    let gpu: Arc<GpuContext> = ctx
        .gpu
        .clone()
        .ok_or_else(|| fatal("the reconstruct job needs a GPU worker"))?;
    let scene = load_scene(&ctx.scene_dir, &LoadOptions::default()).map_err(fatal)?;
    let mut trainer = match ctx.load_checkpoint(CHECKPOINT_NAME).map_err(retryable)? {
        Some(bytes) => {
            let checkpoint = Checkpoint::<TrainerMeta>::from_bytes(&bytes).map_err(retryable)?;
            tracing::info!(step = checkpoint.meta.step, "resuming from checkpoint");
            Trainer::resume(&gpu, &scene, &checkpoint).map_err(train_failure)?
        }
        None => Trainer::new(&gpu, &scene, config.train.clone(), None).map_err(train_failure)?,
    };
    let total = config.train.steps;
    let started = std::time::Instant::now();
    while trainer.step() < total {
        let next_checkpoint = match config.checkpoint_every {
            0 => total,
            every => (trainer.step() / every + 1) * every,
        };
        trainer
            .run_until(next_checkpoint, |progress| {
                report_training(ctx, progress);
                ctx.stop_requested().is_ok()
            })
            .map_err(train_failure)?;
        ctx.stop_requested()?;
        save_checkpoint(ctx, &trainer)?;
    }
    finish(ctx, &mut trainer, started.elapsed().as_secs_f64())
}

fn report_training(ctx: &JobContext, progress: &TrainProgress) {
    let report = Progress {
        stage: "train".to_string(),
        step: progress.step as u64,
        total_steps: progress.total_steps as u64,
        metrics: [
            ("loss".to_string(), progress.loss as f64),
            ("gaussians".to_string(), progress.gaussians as f64),
            ("steps_per_sec".to_string(), progress.steps_per_sec),
        ]
        .into_iter()
        .collect(),
        eta_secs: None,
    };
    if let Err(error) = ctx.progress.report_blocking(report) {
        tracing::warn!(%error, "progress report failed");
    }
}

fn save_checkpoint(ctx: &JobContext, trainer: &Trainer) -> Result<(), JobFailure> {
    let bytes = trainer
        .checkpoint()
        .and_then(|c| Ok(c.to_bytes()?))
        .map_err(train_failure)?;
    ctx.save_checkpoint(CHECKPOINT_NAME, &bytes)
        .map_err(retryable)
}

fn finish(ctx: &JobContext, trainer: &mut Trainer, train_seconds: f64) -> Result<(), JobFailure> {
    let held_out = trainer.evaluate().map_err(train_failure)?;
    let model = trainer.model().map_err(train_failure)?;
    write_scene_files(&model, &ctx.work_dir).map_err(retryable)?;
    let metrics = ReconstructMetrics {
        steps: trainer.step(),
        gaussians: model.len(),
        train_seconds,
        held_out,
    };
    let metrics_json = serde_json::to_vec_pretty(&metrics).map_err(fatal)?;
    let prefix = ctx.output_prefix();
    ctx.blobs
        .put_file(
            &format!("{prefix}/scene.ply"),
            &ctx.work_dir.join("scene.ply"),
        )
        .map_err(retryable)?;
    ctx.blobs
        .put_file(
            &format!("{prefix}/labels.npy"),
            &ctx.work_dir.join("labels.npy"),
        )
        .map_err(retryable)?;
    ctx.blobs
        .put_bytes(&format!("{prefix}/metrics.json"), &metrics_json)
        .map_err(retryable)?;
    let report = Progress {
        stage: "evaluate".to_string(),
        step: 1,
        total_steps: 1,
        metrics: [
            ("psnr".to_string(), metrics.held_out.psnr),
            ("ssim".to_string(), metrics.held_out.ssim),
            ("gaussians".to_string(), metrics.gaussians as f64),
        ]
        .into_iter()
        .collect(),
        eta_secs: None,
    };
    let _ = ctx.progress.report_blocking(report);
    Ok(())
}
