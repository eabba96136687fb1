//! The `segment_then_splat` job: masks per view at three levels -> object ids on the initial
//! Gaussians -> training with the object loss -> CLIP embeddings per object (when a CLIP image
//! model is configured) -> object table. Progress per stage over SSE,
//! checkpoints inside training (a restarted job rebuilds the masks, which is deterministic, and
//! resumes training from its last checkpoint), cancel honoured at step boundaries.
//!
//! Results under the job's output prefix: `scene.ply` (Inria layout), `labels.npy` (object ids
//! per Gaussian, PLY order), `objects.json` (per object: level, id, Gaussian count, centroid,
//! bounds, mean colour), `skipped_pairs.json` (the (frame, level, object) pairs the partial-mask
//! filter left out), `metrics.json`; and the scene's rows in the `objects` and
//! `object_embeddings` tables.

use std::collections::HashSet;
use std::sync::Arc;

use futures::future::BoxFuture;
use serde::{Deserialize, Serialize};

use crate::job_kinds::trainer_setup::{KernelWarmUp, SetupTimer};
use crate::job_kinds::training::{
    StageCadence, TrainingStageReport, fatal, load_resume_point, note_undistortion,
    record_settings, report, report_evaluation, retryable, store_outputs, train_failure,
    train_with_checkpoints,
};
use crate::jobs::{JobContext, JobFailure, JobHandler, Progress};
use crate::store::objects::{ObjectEmbedding, ObjectRecord};
use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::deform::{DEFORMATION_FILE, DEFORMATION_WEIGHTS_FILE};
use segsplat_engine::train::trainer::resolve_adapter_sized;
use segsplat_engine::train::{
    EvalReport, ObjectLossConfig, PartialFilterReport, TrainConfig, Trainer, TrainerMeta,
};
use segsplat_gpu::GpuContext;
use segsplat_method::segment_then_splat::objects::{ObjectSummary, summarize_objects};
use segsplat_method::segment_then_splat::scene_size::{SceneSize, SceneSizedFields};
use segsplat_method::segment_then_splat::training::{
    DEFAULT_OBJECT_FLOORS, SegmentedTrainingOptions, attach_object_training,
    segmented_trainer_from_view_masks, training_frames,
};
use segsplat_method::segment_then_splat::view_masks::ViewMaskSet;
use segsplat_scene::id_runs::replace_ids;
use segsplat_scene::{Level, LoadOptions, Scene, SceneFormat, load_frame_rgb, load_scene};
use segsplat_vision::language::{EmbeddingAccumulator, ObjectView, image_model_id};
use segsplat_vision::models::clip::ClipImageEncoder;
use segsplat_vision::segment::AutomaticConfig;

mod masks;

use masks::{SegmentReport, resolved_mask_source, view_masks_for};

pub const KIND: &str = "segment_then_splat";
const CHECKPOINT_NAME: &str = "train";

/// Where the per-view masks come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskSource {
    /// The scene's own masks when it has them, else SAM-family automatic masks when a SAM model
    /// is configured, else the classical segmenter.
    #[default]
    Auto,
    /// The scene's `masks/{small,middle,large}/` instance-id PNGs (stage 1 is skipped).
    User,
    /// Automatic masks from the configured SAM-family model, associated across views.
    Automatic,
    /// The model-free classical segmenter, associated across views.
    Classical,
    /// SAM-family automatic masks on the first training view, carried through the views in
    /// video order (`scene::sequence::video_order`) by re-prompting the decoder with each
    /// object's previous mask (for sequences: needs no sparse points).
    Propagated,
}

/// The job's config: training settings (the object loss on by default), mask source, the
/// persistence floors and how often to checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentThenSplatConfig {
    #[serde(flatten)]
    pub train: TrainConfig,
    pub masks: MaskSource,
    /// SAM automatic mask generation's settings (`masks` `automatic` and `propagated`, and
    /// `auto` when it picks SAM): the released ones unless given. `points_per_side` is the
    /// stage's cost: the model answers its square, in prompts, on each view it generates on.
    pub automatic: AutomaticConfig,
    /// Gaussians each object keeps at least (small, middle, large), or all it has when fewer.
    pub object_floors: [usize; 3],
    /// Steps between checkpoints (0 = only at the end).
    pub checkpoint_every: u32,
    /// Steps between evaluations of the held-out views while training (0 = only the job's own
    /// at the end): `training.held_out_curve` in metrics.json.
    pub held_out_every: u32,
    /// Fields that follow the scene at run time (docs/method.md: steps of about 100 passes over
    /// the training views, 3k to 30k; one object per level for scenes under 100 training views,
    /// else three; the middle and large levels from the released code's shares of the job).
    /// Filled on submission with the fields the config left out.
    pub scene_sized: SceneSizedFields,
}

impl Default for SegmentThenSplatConfig {
    fn default() -> Self {
        Self {
            train: TrainConfig {
                object_loss: Some(ObjectLossConfig::default()),
                ..TrainConfig::default()
            },
            masks: MaskSource::Auto,
            automatic: AutomaticConfig::default(),
            object_floors: DEFAULT_OBJECT_FLOORS,
            checkpoint_every: 1000,
            held_out_every: 0,
            scene_sized: SceneSizedFields::default(),
        }
    }
}

impl SegmentThenSplatConfig {
    fn cadence(&self) -> StageCadence {
        StageCadence {
            checkpoint_every: self.checkpoint_every,
            held_out_every: self.held_out_every,
        }
    }
}

/// What a finished job reports in `metrics.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SegmentThenSplatMetrics {
    pub steps: u32,
    pub gaussians: usize,
    pub train_seconds: f64,
    /// The training stage's host costs per step and its Gaussian budget.
    #[serde(default)]
    pub training: TrainingStageReport,
    pub held_out: EvalReport,
    /// Objects per level (small, middle, large).
    pub objects: [usize; 3],
    pub skipped_pairs: usize,
    /// What the partial-mask filter found: pairs checked and left out per level, IoU quartiles,
    /// and the left-out pairs whose object renders nothing in the view (absent when it did not
    /// run, and in metrics written before it was reported).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub partial_filter: Option<PartialFilterReport>,
    /// Stage 1: the mask source used and its figures (as the "segment" stage reported them).
    pub segment: SegmentReport,
    /// The settings the job ran with (also the job's `settings`; absent in metrics written
    /// before they were kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings: Option<SegmentThenSplatConfig>,
}

/// A skipped (object, view) pair in frame terms.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct SkippedFramePair {
    frame_index: usize,
    frame_name: String,
    level: Level,
    object_id: u32,
}

#[derive(Debug, Default)]
pub struct SegmentThenSplatHandler;

impl JobHandler for SegmentThenSplatHandler {
    fn kind(&self) -> &'static str {
        KIND
    }

    fn validate_config(&self, config: &serde_json::Value) -> Result<serde_json::Value, String> {
        let mut parsed: SegmentThenSplatConfig = if config.is_null() {
            SegmentThenSplatConfig::default()
        } else {
            serde_json::from_value(config.clone()).map_err(|error| error.to_string())?
        };
        if config.get("scene_sized").is_none() {
            parsed.scene_sized = SceneSizedFields::left_out_of(config);
        }
        // The object loss is the point of this job: on unless configured.
        parsed
            .train
            .object_loss
            .get_or_insert_with(ObjectLossConfig::default);
        parsed.train.validate().map_err(|error| error.to_string())?;
        parsed
            .automatic
            .validate()
            .map_err(|error| error.to_string())?;
        serde_json::to_value(&parsed).map_err(|error| error.to_string())
    }

    fn run(&self, ctx: JobContext) -> BoxFuture<'static, Result<(), JobFailure>> {
        Box::pin(async move {
            let ctx = Arc::new(ctx);
            let worker = Arc::clone(&ctx);
            let (objects, embeddings) = tokio::task::spawn_blocking(move || run_blocking(&worker))
                .await
                .map_err(|error| retryable(format!("worker thread failed: {error}")))??;
            ctx.database
                .replace_objects(&ctx.scene_id, &objects, &embeddings)
                .await
                .map_err(retryable)?;
            let persisted = Progress {
                stage: "persist".to_string(),
                step: 1,
                total_steps: 1,
                metrics: [
                    ("objects".to_string(), objects.len() as f64),
                    ("embeddings".to_string(), embeddings.len() as f64),
                ]
                .into_iter()
                .collect(),
                eta_secs: None,
            };
            if let Err(error) = ctx.progress.report(persisted).await {
                tracing::warn!(%error, "progress report failed");
            }
            Ok(())
        })
    }
}

fn run_blocking(ctx: &JobContext) -> Result<(Vec<ObjectRecord>, Vec<ObjectEmbedding>), JobFailure> {
    let mut config: SegmentThenSplatConfig =
        serde_json::from_value(ctx.config.clone()).map_err(fatal)?;
    let gpu: Arc<GpuContext> = ctx
        .gpu
        .clone()
        .ok_or_else(|| fatal("the segment_then_splat job needs a GPU worker"))?;
    let scene = load_scene(&ctx.scene_dir, &LoadOptions::default()).map_err(fatal)?;
    note_undistortion(ctx, &scene);
    let frames = training_frames(&scene, &config.train);
    let size = SceneSize::of(frames.len());
    config.scene_sized.apply(frames.len(), &mut config.train);
    config
        .scene_sized
        .apply_deformation(scene.is_dynamic(), &mut config.train);
    let rgba = scene.format == SceneFormat::Blender;
    config
        .scene_sized
        .apply_background(rgba.then_some(scene.background), &mut config.train);
    resolve_adapter_sized(&mut config.train, &scene, &gpu);
    tracing::info!(
        ?size,
        steps = config.train.steps,
        objects_per_level = config
            .train
            .object_loss
            .as_ref()
            .map(|o| o.objects_per_level),
        dynamic = config.train.deformation.is_some(),
        "training settings"
    );
    // What the job runs with, `auto` and the scene-sized fields resolved: shown beside the
    // config it was created with, and kept in metrics.json.
    let mut settings = SegmentThenSplatConfig {
        masks: resolved_mask_source(ctx, &scene, config.masks),
        ..config.clone()
    };
    record_settings(ctx, &settings);
    // Stage 1 runs again on a resumed attempt: every mask source is deterministic, and the
    // masks are cheaper to rebuild than to store.
    // The trainer's kernels compile beside the masks (they need nothing from them).
    let warm_up = KernelWarmUp::start(&gpu, &config.train);
    let (masks, segmented, carved_hulls) = view_masks_for(ctx, &scene, &config, &frames)?;
    // Between stages too: building the trainer uploads and sorts every view's masks.
    ctx.stop_requested()?;
    let options = SegmentedTrainingOptions {
        object_floors: config.object_floors,
        background_shell: config.train.background_shell,
        ..SegmentedTrainingOptions::default()
    };
    let setup = SetupTimer::start(&gpu, Some(warm_up));
    let mut trainer = match load_resume_point(ctx, CHECKPOINT_NAME)? {
        Some(checkpoint) => resume_segmented(&gpu, &scene, &checkpoint, &masks, &options)?,
        None => segmented_trainer_from_view_masks(
            &gpu,
            &scene,
            config.train.clone(),
            &masks,
            &options,
            carved_hulls,
        )
        .map_err(fatal)?,
    };
    // A resumed attempt trains on with its checkpoint's settings, which differ from those just
    // resolved where an adapter-sized value (the random start, the field's shape) was resolved
    // on another kind of worker: the job says what runs.
    if trainer.config() != &settings.train {
        settings.train = trainer.config().clone();
        record_settings(ctx, &settings);
    }
    let setup = setup.finish(&gpu);
    ctx.stop_requested()?;
    let training = train_with_checkpoints(ctx, &mut trainer, CHECKPOINT_NAME, config.cadence())?
        .with_setup(setup);
    let objects = finish(ctx, &scene, &mut trainer, training, segmented, settings)?;
    let embeddings = embed_objects(ctx, &scene, &trainer, &masks, &objects)?;
    Ok((objects, embeddings))
}

/// The "embed" stage: one CLIP embedding per object (docs/method.md stage 4, see
/// [`segsplat_vision::language::embedding`]) from the training views at the training resolution and their
/// masks, leaving out the pairs the partial-mask filter skipped. Without a CLIP image model it
/// is skipped (logged and reported): the objects are still stored, and queries answer "no text
/// encoder configured".
fn embed_objects(
    ctx: &JobContext,
    scene: &Scene,
    trainer: &Trainer,
    masks: &ViewMaskSet,
    objects: &[ObjectRecord],
) -> Result<Vec<ObjectEmbedding>, JobFailure> {
    let Some(model_id) = image_model_id(&ctx.models) else {
        tracing::info!("no CLIP image model configured: objects are stored without embeddings");
        report(ctx, "embed", 0, 0, &[("skipped_no_clip_model", 1.0)]);
        return Ok(Vec::new());
    };
    let store = ctx.models.store().map_err(fatal)?;
    let encoder = ClipImageEncoder::new(store).map_err(fatal)?;
    let max_side = trainer.config().max_resolution;
    let skipped: HashSet<(usize, Level, u32)> = trainer
        .skipped_pairs()
        .into_iter()
        .map(|pair| (pair.train_view, pair.level, pair.object_id))
        .collect();
    let kept: HashSet<(Level, u32)> = objects
        .iter()
        .map(|object| (object.level, object.object_id))
        .collect();
    let total = masks.views.len() as u64;
    report(ctx, "embed", 0, total, &[]);
    let mut accumulator = EmbeddingAccumulator::default();
    for (view_index, view) in masks.views.iter().enumerate() {
        ctx.stop_requested()?;
        let image = load_frame_rgb(scene, view.frame_index, max_side).map_err(retryable)?;
        let image = image::DynamicImage::ImageRgb32F(image).into_rgb8();
        // Only objects that kept Gaussians can answer a query: the others are not embedded.
        let mut ids = view.level_ids();
        for (level, level_ids) in Level::ALL.into_iter().zip(&mut ids) {
            replace_ids(level_ids, |id| (!kept.contains(&(level, id))).then_some(0));
        }
        let object_view = ObjectView {
            image: &image,
            ids: [&ids[0][..], &ids[1][..], &ids[2][..]],
        };
        accumulator
            .add_view(
                view_index,
                &object_view,
                |view, level, id| skipped.contains(&(view, level, id)),
                &encoder,
            )
            .map_err(fatal)?;
        report(ctx, "embed", view_index as u64 + 1, total, &[]);
    }
    let vectors = accumulator.finish();
    let from_skipped = vectors.iter().filter(|v| v.from_skipped_views).count();
    tracing::info!(objects = vectors.len(), from_skipped, model = %model_id, "objects embedded");
    report(
        ctx,
        "embed",
        total,
        total,
        &[
            ("objects", vectors.len() as f64),
            ("from_skipped_views", from_skipped as f64),
        ],
    );
    Ok(vectors
        .into_iter()
        .map(|object| ObjectEmbedding {
            scene_id: ctx.scene_id.clone(),
            level: object.level,
            object_id: object.object_id,
            model_id: model_id.clone(),
            vector: object.vector,
        })
        .collect())
}

/// A trainer continuing from a checkpoint: the masks are rebuilt (deterministic) and the
/// persistence floor set again; everything else comes from the checkpoint.
fn resume_segmented(
    gpu: &GpuContext,
    scene: &Scene,
    checkpoint: &Checkpoint<TrainerMeta>,
    masks: &ViewMaskSet,
    options: &SegmentedTrainingOptions,
) -> Result<Trainer, JobFailure> {
    let mut trainer = Trainer::resume(gpu, scene, checkpoint).map_err(train_failure)?;
    attach_object_training(gpu, &mut trainer, masks, options).map_err(fatal)?;
    Ok(trainer)
}

fn finish(
    ctx: &JobContext,
    scene: &Scene,
    trainer: &mut Trainer,
    training: TrainingStageReport,
    segment: SegmentReport,
    settings: SegmentThenSplatConfig,
) -> Result<Vec<ObjectRecord>, JobFailure> {
    let held_out = trainer.evaluate().map_err(train_failure)?;
    let model = trainer.model().map_err(train_failure)?;
    // A dynamic scene's objects are summarised where they are at its first time (queries at
    // other times compute their own); its field is stored next to the canonical Gaussians.
    let times = scene.frame_times();
    let first_time = times.first().copied().unwrap_or(0.0);
    let summaries = summarize_objects(&trainer.model_at(first_time).map_err(train_failure)?);
    let deformation = trainer.stored_deformation(&times).map_err(train_failure)?;
    let skipped: Vec<SkippedFramePair> = trainer
        .skipped_pairs()
        .into_iter()
        .filter_map(|pair| {
            let frame_index = trainer.views().train.get(pair.train_view)?.frame_index;
            Some(SkippedFramePair {
                frame_index,
                frame_name: scene.frames.get(frame_index)?.name.clone(),
                level: pair.level,
                object_id: pair.object_id,
            })
        })
        .collect();
    let metrics = SegmentThenSplatMetrics {
        steps: trainer.step(),
        gaussians: model.len(),
        train_seconds: training.seconds,
        training,
        held_out,
        objects: Level::ALL.map(|level| summaries.iter().filter(|s| s.level == level).count()),
        skipped_pairs: skipped.len(),
        partial_filter: trainer.partial_filter_report().cloned(),
        segment,
        settings: Some(settings),
    };
    let documents = [
        (
            "objects.json",
            serde_json::to_vec_pretty(&summaries).map_err(fatal)?,
        ),
        (
            "skipped_pairs.json",
            serde_json::to_vec_pretty(&skipped).map_err(fatal)?,
        ),
        (
            "metrics.json",
            serde_json::to_vec_pretty(&metrics).map_err(fatal)?,
        ),
    ];
    let mut documents = documents.to_vec();
    if let Some(deformation) = &deformation {
        documents.push((DEFORMATION_FILE, deformation.header_bytes().map_err(fatal)?));
        documents.push((DEFORMATION_WEIGHTS_FILE, deformation.weight_bytes()));
    }
    store_outputs(ctx, &model, scene, &documents)?;
    report_evaluation(ctx, &metrics.held_out, metrics.gaussians);
    Ok(summaries
        .iter()
        .map(|summary| object_record(&ctx.scene_id, summary))
        .collect())
}

fn object_record(scene_id: &str, summary: &ObjectSummary) -> ObjectRecord {
    ObjectRecord {
        scene_id: scene_id.to_string(),
        level: summary.level,
        object_id: summary.object_id,
        gaussian_count: summary.gaussian_count as u64,
        centroid: summary.centroid,
        bounds_min: summary.bounds_min,
        bounds_max: summary.bounds_max,
        mean_color: summary.mean_color,
    }
}
