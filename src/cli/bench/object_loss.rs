//! `bench --object-loss`: a trainer with the Segment-then-Splat object loss on every level from
//! the first step, and the plain trainer on the same starting Gaussians that it is timed against.

use segsplat_engine::GaussianModel;
use segsplat_engine::train::{PartialFilterReport, TrainConfig, Trainer};
use segsplat_gpu::GpuContext;
use segsplat_scene::Scene;
use serde::Serialize;

use super::profile::KernelProfileReport;

#[derive(Serialize)]
pub(super) struct ObjectLossReport {
    objects_per_level: u32,
    /// `batched` (on the step's full render) or `separate` (`--separate-object-renders`).
    renders: &'static str,
    /// `user` or `classical`.
    masks: &'static str,
    /// Objects per level (small, middle, large).
    objects: [usize; 3],
    mask_seconds: f64,
}

/// A trainer with the object loss on every level from the start, and what it trains on.
pub(super) fn object_loss_trainer(
    ctx: &GpuContext,
    scene: &Scene,
    mut config: TrainConfig,
    initial: Option<GaussianModel>,
    objects_per_level: u32,
    separate_renders: bool,
) -> anyhow::Result<(Trainer, ObjectLossReport)> {
    use segsplat_engine::train::ObjectLossConfig;
    use segsplat_method::segment_then_splat::association::{
        AssociationOptions, generated_view_masks,
    };
    use segsplat_method::segment_then_splat::carved_hulls::CarvedHulls;
    use segsplat_method::segment_then_splat::training::{
        SegmentedTrainingOptions, attach_object_training, segmented_trainer_from_view_masks,
        training_frames,
    };
    use segsplat_method::segment_then_splat::view_masks::ViewMaskSet;
    use segsplat_vision::segment::{ClassicalConfig, MaskGenerator};

    anyhow::ensure!(
        objects_per_level > 0,
        "--objects-per-level must be at least 1"
    );
    // The partial-mask filter runs after the last step, where its time is reported apart: on a
    // short, untrained run it leaves out most pairs (88% at 200 steps, against about a tenth on
    // a trained scene), which would make the steps after it unrepresentatively cheap.
    config.object_loss = Some(ObjectLossConfig {
        objects_per_level,
        middle_from: 0.0,
        large_from: 0.0,
        partial_filter_from: 1.0,
        ..ObjectLossConfig::default()
    });
    let started = std::time::Instant::now();
    let frames = training_frames(scene, &config);
    let (masks, source) = if scene.masks.is_some() {
        let masks = ViewMaskSet::from_user_masks(scene, &frames, config.max_resolution)?;
        (masks, "user")
    } else {
        let mut generator = MaskGenerator::Classical(ClassicalConfig::default());
        let (masks, _) = generated_view_masks(
            scene,
            &frames,
            &mut generator,
            config.max_resolution,
            &AssociationOptions::default(),
        )?;
        (masks, "classical")
    };
    let mask_seconds = started.elapsed().as_secs_f64();
    let options = SegmentedTrainingOptions::default();
    let mut trainer = match initial {
        // Random Gaussians carry no ids: the object loss then renders empty objects, which
        // still costs the renders it measures.
        Some(model) => {
            let mut trainer = Trainer::new(ctx, scene, config, Some(model))?;
            attach_object_training(ctx, &mut trainer, &masks, &options)?;
            trainer
        }
        None => segmented_trainer_from_view_masks(
            ctx,
            scene,
            config,
            &masks,
            &options,
            CarvedHulls::default(),
        )?,
    };
    trainer.set_separate_object_renders(separate_renders);
    let objects = segsplat_scene::Level::ALL.map(|level| masks.object_count(level));
    Ok((
        trainer,
        ObjectLossReport {
            objects_per_level,
            renders: if separate_renders {
                "separate"
            } else {
                "batched"
            },
            masks: source,
            objects,
            mask_seconds,
        },
    ))
}

/// The plain step on the object-loss run's own starting Gaussians (background shell included),
/// so the ratio compares like with like.
#[derive(Serialize)]
pub(super) struct PlainBaselineReport {
    pub(super) gaussians_start: usize,
    pub(super) steps_per_sec: f64,
    pub(super) dispatches_per_step: f64,
    pub(super) psnr: f64,
    /// Object-loss step time over plain step time, the partial-mask filter's one-off time left
    /// out of the object-loss side (it is a stage of the job, not part of a step).
    pub(super) step_time_ratio: f64,
    /// The same with the filter's time counted in the object-loss steps (what a job of exactly
    /// this many steps pays).
    pub(super) step_time_ratio_with_filter: f64,
    /// Wall seconds of the partial-mask filter (every (object, view) pair rendered once, after
    /// the last step here), inside the object-loss run's `train_seconds`.
    pub(super) partial_filter_seconds: f64,
    /// Its kernel dispatches (not in `dispatches_per_step`).
    pub(super) partial_filter_dispatches: u64,
    /// What it found: pairs and left-out pairs per level, IoU quartiles, left-out pairs whose
    /// object renders nothing (as in a job's metrics.json).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) partial_filter: Option<PartialFilterReport>,
    /// Object-loss dispatches per step over plain dispatches per step.
    pub(super) dispatch_ratio: f64,
    /// With `--profile-kernels`: the plain trainer's kernels over as many more steps, after its
    /// timed run, to set beside the object-loss run's `kernel_profile`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) kernel_profile: Option<KernelProfileReport>,
}

/// The plain half of `--object-loss`: `config` without the object loss, from `model`.
pub(super) fn plain_trainer(
    ctx: &GpuContext,
    scene: &Scene,
    config: &TrainConfig,
    model: GaussianModel,
    timing_repeats: u32,
) -> anyhow::Result<Trainer> {
    // At the object run's resolution throughout: without the object loss the schedule would
    // otherwise start coarse, and the ratio would compare steps of different sizes.
    let config = TrainConfig {
        object_loss: None,
        coarse_until: Some(0),
        ..config.clone()
    };
    let mut trainer = Trainer::new(ctx, scene, config, Some(model))?;
    // The same warm-up as the timed run gets, so neither pays first-use costs in its loop.
    trainer.time_passes(timing_repeats)?;
    Ok(trainer)
}
