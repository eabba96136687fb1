//! The `reconstruct` job: plain 3DGS on an uploaded scene. Resumes from its last checkpoint
//! (saved every `checkpoint_every` steps to the blob store), reports progress at every sync point,
//! honours cancel at those step boundaries, and leaves `scene.ply` (Inria layout), `labels.npy`
//! and `metrics.json` under the job's output prefix.

use std::sync::Arc;

use futures::future::BoxFuture;
use serde::{Deserialize, Serialize};

use super::training::{
    StageCadence, TrainingStageReport, fatal, load_resume_point, note_undistortion,
    record_settings, report_evaluation, store_outputs, train_failure, train_with_checkpoints,
};
use crate::job_kinds::trainer_setup::SetupTimer;
use crate::jobs::{JobContext, JobFailure, JobHandler};
use segsplat_engine::deform::{DEFORMATION_FILE, DEFORMATION_WEIGHTS_FILE, DeformationConfig};
use segsplat_engine::train::{TrainConfig, Trainer};
use segsplat_gpu::GpuContext;
use segsplat_method::scene_files::ReconstructMetrics;
use segsplat_scene::{LoadOptions, Scene, load_scene};

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
    /// Steps between evaluations of the held-out views while training (0 = only the job's own
    /// at the end): `training.held_out_curve` in metrics.json.
    pub held_out_every: u32,
    /// Set on submission when the config left `deformation` out: a dynamic scene then trains
    /// with the default deformation field for the worker's adapter (`"deformation": null`
    /// keeps it static).
    pub deformation_from_scene: bool,
}

impl Default for ReconstructConfig {
    fn default() -> Self {
        Self {
            train: TrainConfig::default(),
            checkpoint_every: 1000,
            held_out_every: 0,
            deformation_from_scene: false,
        }
    }
}

impl ReconstructConfig {
    fn cadence(&self) -> StageCadence {
        StageCadence {
            checkpoint_every: self.checkpoint_every,
            held_out_every: self.held_out_every,
        }
    }
}

#[derive(Debug, Default)]
pub struct ReconstructHandler;

impl JobHandler for ReconstructHandler {
    fn kind(&self) -> &'static str {
        KIND
    }

    fn validate_config(&self, config: &serde_json::Value) -> Result<serde_json::Value, String> {
        let mut parsed: ReconstructConfig = if config.is_null() {
            ReconstructConfig::default()
        } else {
            serde_json::from_value(config.clone()).map_err(|error| error.to_string())?
        };
        if config.get("deformation_from_scene").is_none() {
            parsed.deformation_from_scene = config.get("deformation").is_none();
        }
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

fn run_blocking(ctx: &JobContext) -> Result<(), JobFailure> {
    let mut config: ReconstructConfig =
        serde_json::from_value(ctx.config.clone()).map_err(fatal)?;
    let gpu: Arc<GpuContext> = ctx
        .gpu
        .clone()
        .ok_or_else(|| fatal("the reconstruct job needs a GPU worker"))?;
    let scene = load_scene(&ctx.scene_dir, &LoadOptions::default()).map_err(fatal)?;
    note_undistortion(ctx, &scene);
    if config.deformation_from_scene && scene.is_dynamic() && config.train.deformation.is_none() {
        config.train.deformation = Some(DeformationConfig::default());
    }
    // No stage comes before the trainer to compile its kernels beside; a worker's context
    // still keeps them for its later jobs.
    let setup = SetupTimer::start(&gpu, None);
    let mut trainer = match load_resume_point(ctx, CHECKPOINT_NAME)? {
        Some(checkpoint) => Trainer::resume(&gpu, &scene, &checkpoint).map_err(train_failure)?,
        None => Trainer::new(&gpu, &scene, config.train.clone(), None).map_err(train_failure)?,
    };
    let settings = ReconstructSettings {
        train: trainer.config().clone(),
        gaussian_budget: trainer.gaussian_budget(),
        checkpoint_every: config.checkpoint_every,
    };
    let setup = setup.finish(&gpu);
    record_settings(ctx, &settings);
    let training = train_with_checkpoints(ctx, &mut trainer, CHECKPOINT_NAME, config.cadence())?
        .with_setup(setup);
    finish(ctx, &scene, &mut trainer, training, settings)
}

/// What a reconstruct job runs with: the training settings as the trainer resolved them, and
/// the Gaussian budget it sized from the scene when the config left it out.
#[derive(Debug, Clone, Serialize)]
struct ReconstructSettings {
    train: TrainConfig,
    gaussian_budget: usize,
    checkpoint_every: u32,
}

/// A reconstruct job's metrics.json: the training command's metrics and the training stage's
/// host costs.
#[derive(Serialize)]
struct ReconstructJobMetrics<'a> {
    #[serde(flatten)]
    metrics: &'a ReconstructMetrics,
    training: TrainingStageReport,
    /// The settings it ran with (also the job's `settings`).
    settings: ReconstructSettings,
}

fn finish(
    ctx: &JobContext,
    scene: &Scene,
    trainer: &mut Trainer,
    training: TrainingStageReport,
    settings: ReconstructSettings,
) -> Result<(), JobFailure> {
    let held_out = trainer.evaluate().map_err(train_failure)?;
    let model = trainer.model().map_err(train_failure)?;
    let metrics = ReconstructMetrics {
        steps: trainer.step(),
        gaussians: model.len(),
        train_seconds: training.seconds,
        held_out,
    };
    let metrics_json = serde_json::to_vec_pretty(&ReconstructJobMetrics {
        metrics: &metrics,
        training,
        settings,
    })
    .map_err(fatal)?;
    let mut documents = vec![("metrics.json", metrics_json)];
    // A config with `deformation` trains a dynamic scene's field; it is stored with the scene.
    if let Some(stored) = trainer
        .stored_deformation(&scene.frame_times())
        .map_err(train_failure)?
    {
        documents.push((DEFORMATION_FILE, stored.header_bytes().map_err(fatal)?));
        documents.push((DEFORMATION_WEIGHTS_FILE, stored.weight_bytes()));
    }
    store_outputs(ctx, &model, scene, &documents)?;
    report_evaluation(ctx, &metrics.held_out, metrics.gaussians);
    Ok(())
}
