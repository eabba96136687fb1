//! `segsplat bench DIR`: trains plain 3DGS (or, with `--object-loss`, with the Segment-then-Splat
//! object loss on the dataset's own or classical masks) and reports speed and held-out quality as
//! one JSON object (see the README for figures measured with it). With `--deformation` it trains
//! the same Gaussians twice, as a static scene and with the deformation field, and reports what
//! the field costs per step.

mod curve;
pub mod matmul;

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use glam::Vec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use segsplat_engine::GaussianModel;
use segsplat_engine::deform::{
    DeformationConfig, FieldShape, GemmKernel, MatmulReport, measure_matmul,
};
use segsplat_engine::init::random_gaussians;
use segsplat_engine::ply::read_ply_file;
use segsplat_engine::train::convergence::ConvergenceStop;
use segsplat_engine::train::trainer::initial_model;
use segsplat_engine::train::{ConvergedAt, PartialFilterReport, TrainConfig, Trainer};
use segsplat_gpu::profiler::KernelTime;
use segsplat_gpu::{GpuContext, HostCostReading};
use segsplat_scene::Scene;
use segsplat_service::job_kinds::training::BUSY_TIMELINE_STEPS;
use serde::Serialize;

#[derive(Args)]
pub struct BenchArgs {
    pub dataset: PathBuf,
    #[arg(long, default_value_t = 500)]
    pub steps: u32,
    #[arg(long, default_value_t = 256)]
    pub max_resolution: u32,
    #[arg(long, default_value_t = 8)]
    pub eval_split_every: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Render passes timed for the forward / backward figures.
    #[arg(long, default_value_t = 10)]
    pub timing_repeats: u32,
    /// Start from this many random Gaussians inside the sparse points' bounding box (the
    /// cameras' bounds when the dataset has no points) instead of the points themselves, to
    /// measure how step time scales with the Gaussian count at a realistic splat density.
    #[arg(long, conflicts_with = "init_ply")]
    pub init_random: Option<usize>,
    /// Start from the Gaussians of a splat PLY (a trained scene of this dataset, e.g. the
    /// `scene.ply` of `segsplat train`), to time steps at a trained scene's density.
    #[arg(long)]
    pub init_ply: Option<PathBuf>,
    /// Keep the Gaussian count fixed (no densification, pruning or opacity reset).
    #[arg(long)]
    pub no_densify: bool,
    /// Train with the object loss: `m` objects per level per step at every level from the
    /// first step (the most it costs), on the dataset's masks or else classical masks.
    #[arg(long)]
    pub object_loss: bool,
    /// `m` for `--object-loss`.
    #[arg(long, default_value_t = 3)]
    pub objects_per_level: u32,
    /// Stop before `--steps` when the fit of a few training views stops gaining (the
    /// convergence stop a `segment_then_splat` job without `steps` uses; `--steps` is then the
    /// ceiling); the report gives `converged_at` and every check in `fit_checks`.
    #[arg(long)]
    pub converge: bool,
    /// Render each object of `--object-loss` separately (its own projection, depth sort and
    /// backward: the path before batching) rather than batched on the step's full render, to
    /// compare the two in one build.
    #[arg(long, requires = "object_loss")]
    pub separate_object_renders: bool,
    /// Also train with the deformation field moving the Gaussians from step 0 (no warm-up),
    /// after a static run with the same Gaussians, resolution, steps and seed, and report the
    /// field's cost (`deformation` in the report; the other figures are the run with the
    /// field). A static dataset works too: every view then has time 0, which costs the same.
    #[arg(long)]
    pub deformation: bool,
    /// Layers of the deformation field (default: the shape a job's field gets on this
    /// adapter, 8 x 256 on a GPU and 4 x 64 on a software adapter, docs/engine.md); the input
    /// skip joins after depth / 2 (no skip below depth 4).
    #[arg(long, requires = "deformation")]
    pub field_depth: Option<u32>,
    /// Width of the deformation field's hidden layers (default: as `--field-depth`).
    #[arg(long, requires = "deformation")]
    pub field_width: Option<u32>,
    /// After training and evaluation, time every kernel over this many more training steps
    /// with GPU timestamps (`kernel_profile` in the report: ms per step by kernel), after
    /// `--busy-steps` steps with only their passes timed (`kernel_profile.timeline`: how full
    /// the host kept the GPU, `gpu_busy_fraction`).
    #[arg(long)]
    pub profile_kernels: Option<u32>,
    /// Steps `--profile-kernels` runs with their passes timed for `gpu_busy_fraction` (a job
    /// samples as many, fewer in a short stage).
    #[arg(long, default_value_t = BUSY_TIMELINE_STEPS, requires = "profile_kernels")]
    pub busy_steps: u32,
    /// A TOML file of training settings (the keys of a job's `train` config, e.g.
    /// `max_sh_degree = 1` or `[densify]` values) to bench instead of the defaults; `--steps`,
    /// `--max-resolution`, `--eval-split-every` and `--seed` still apply on top.
    #[arg(long)]
    pub train_config: Option<PathBuf>,
    /// Evaluate the held-out views every this many steps (`curve` in the report: PSNR against
    /// training time; evaluations are not timed).
    #[arg(long, conflicts_with_all = ["object_loss", "deformation"])]
    pub eval_every: Option<u32>,
    /// Train on wgpu's no-op device (`GpuContext::new_noop`): every dispatch recorded,
    /// validated and submitted, none run. The `host` figures are then the host's side of a step
    /// alone, as on a GPU that took no time; quality figures mean nothing. Implies
    /// `--no-densify`: with every kernel's output zero, densification would prune the whole
    /// model.
    #[arg(long, conflicts_with = "profile_kernels")]
    pub noop_device: bool,
    /// Print one JSON object (otherwise a readable summary).
    #[arg(long)]
    pub json: bool,
}

/// The training settings of `--train-config`, or the defaults.
fn base_train_config(args: &BenchArgs) -> anyhow::Result<TrainConfig> {
    let Some(path) = &args.train_config else {
        return Ok(TrainConfig::default());
    };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("{} is no training config", path.display()))
}

#[derive(Serialize)]
struct ObjectLossReport {
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
fn object_loss_trainer(
    ctx: &segsplat_gpu::GpuContext,
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

/// `count` random Gaussians spread uniformly over the box holding the central 98% of the sparse
/// points per axis (outliers would stretch it over empty space); without points, 3DGS's random
/// initialisation in the cameras' bounds.
fn random_model_in_points_bounds(scene: &mut Scene, count: usize, seed: u64) -> GaussianModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xbe_c4);
    match scene.points.take() {
        Some(points) if !points.positions.is_empty() => {
            let bound = |axis: usize, quantile: f32| {
                let mut values: Vec<f32> = points.positions.iter().map(|p| p[axis]).collect();
                values.sort_unstable_by(f32::total_cmp);
                values[((values.len() - 1) as f32 * quantile) as usize]
            };
            let min = Vec3::new(bound(0, 0.01), bound(1, 0.01), bound(2, 0.01));
            let max = Vec3::new(bound(0, 0.99), bound(1, 0.99), bound(2, 0.99));
            random_gaussians(count, min, max, &mut rng)
        }
        _ => {
            let config = TrainConfig {
                random_init_count: Some(count),
                seed,
                ..TrainConfig::default()
            };
            initial_model(scene, &config).unwrap_or_default()
        }
    }
}

/// What the deformation field costs: the same run with and without it.
#[derive(Serialize)]
struct DeformationReport {
    field: FieldShape,
    parameters: usize,
    /// Distinct times among the training views (1 for a static dataset).
    training_times: usize,
    /// With the field (equal to the report's `steps_per_sec`).
    steps_per_sec: f64,
    train_seconds: f64,
    /// The same steps on the same Gaussians without the field.
    static_steps_per_sec: f64,
    static_train_seconds: f64,
    static_psnr: f64,
    /// Dynamic step time over static step time: the step with the field takes this many
    /// times as long.
    step_time_ratio: f64,
    /// Mean wall time of the field's forward pass over every Gaussian, and of its backward
    /// pass (Adam excluded), each submitted and waited for, after training.
    field_forward_ms: f64,
    field_backward_ms: f64,
    /// The GEMM kernel the field ran (`tiled`, `rows` or `broadcast`).
    gemm_kernel: String,
    /// Floating-point operations of the field's matrix products in one step at the end's
    /// Gaussian count, forward and backward (`FieldShape::flops_per_gaussian`), in GFLOP.
    field_gflop_per_step: f64,
    /// `field_gflop_per_step` over `field_forward_ms + field_backward_ms`: the rate the field's
    /// passes reached, everything in them counted (encoding, bias sums, split reductions).
    field_gflops: f64,
    /// The same kernel on one 256-wide layer over 16,384 Gaussians in this run (`segsplat
    /// bench-matmul`): the adapter's own rate with it.
    matmul: MatmulReport,
    /// `field_gflops / matmul.gflops`.
    field_rate_fraction: f64,
}

#[derive(Serialize)]
struct BenchReport {
    adapter: String,
    backend: String,
    image_width: u32,
    image_height: u32,
    train_views: usize,
    test_views: usize,
    steps: u32,
    gaussians_start: usize,
    gaussians_end: usize,
    /// Gaussians densification may grow to (the config's, or the scene's).
    gaussian_budget: usize,
    /// Mean wall time of one forward render (submit to completion), at the start and the end.
    forward_ms_start: f64,
    forward_ms_end: f64,
    /// Mean wall time of loss + backward, at the start and the end.
    backward_ms_start: f64,
    backward_ms_end: f64,
    /// Training loop only (setup, timing and evaluation excluded).
    steps_per_sec: f64,
    /// Kernel dispatches recorded by the training loop, per step.
    dispatches_per_step: f64,
    /// The host's side of the training loop, per step.
    host: HostCostReport,
    train_seconds: f64,
    psnr: f64,
    ssim: f64,
    /// The worst held-out view's PSNR.
    worst_psnr: f64,
    peak_resident_mib: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    object_loss: Option<ObjectLossReport>,
    /// With `--object-loss`: the same Gaussians trained without the object loss, in turns with
    /// the object-loss run.
    #[serde(skip_serializing_if = "Option::is_none")]
    plain_baseline: Option<PlainBaselineReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    deformation: Option<DeformationReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    kernel_profile: Option<KernelProfileReport>,
    /// With `--eval-every`: held-out quality along the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    curve: Option<Vec<curve::CurvePoint>>,
    /// With a convergence stop (`--converge`, or a config's `stop_when_converged`): where it
    /// ended the run, and the check views' fit at every check (step, mean PSNR).
    #[serde(skip_serializing_if = "Option::is_none")]
    converged_at: Option<ConvergedAt>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    fit_checks: Vec<(u32, f64)>,
}

/// The plain step on the object-loss run's own starting Gaussians (background shell included),
/// so the ratio compares like with like.
#[derive(Serialize)]
struct PlainBaselineReport {
    gaussians_start: usize,
    steps_per_sec: f64,
    dispatches_per_step: f64,
    psnr: f64,
    /// Object-loss step time over plain step time, the partial-mask filter's one-off time left
    /// out of the object-loss side (it is a stage of the job, not part of a step).
    step_time_ratio: f64,
    /// The same with the filter's time counted in the object-loss steps (what a job of exactly
    /// this many steps pays).
    step_time_ratio_with_filter: f64,
    /// Wall seconds of the partial-mask filter (every (object, view) pair rendered once, after
    /// the last step here), inside the object-loss run's `train_seconds`.
    partial_filter_seconds: f64,
    /// Its kernel dispatches (not in `dispatches_per_step`).
    partial_filter_dispatches: u64,
    /// What it found: pairs and left-out pairs per level, IoU quartiles, left-out pairs whose
    /// object renders nothing (as in a job's metrics.json).
    #[serde(skip_serializing_if = "Option::is_none")]
    partial_filter: Option<PartialFilterReport>,
    /// Object-loss dispatches per step over plain dispatches per step.
    dispatch_ratio: f64,
    /// With `--profile-kernels`: the plain trainer's kernels over as many more steps, after its
    /// timed run, to set beside the object-loss run's `kernel_profile`.
    #[serde(skip_serializing_if = "Option::is_none")]
    kernel_profile: Option<KernelProfileReport>,
}

/// Trains `steps` on `trainer`, returning its progress and the dispatches it recorded per step,
/// the partial-mask filter's left out (a stage of the job, reported apart).
/// Steps of one trainer between turns when two are timed together.
const INTERLEAVED_STEPS: u32 = 25;

/// One trainer's timed training loop.
#[derive(Debug, Default, Clone, Copy)]
struct TimedRun {
    steps: u32,
    seconds: f64,
    /// Kernel dispatches per step, the partial-mask filter's left out.
    dispatches_per_step: f64,
    /// What the host waited for and read back over the run.
    host: HostCostReading,
}

impl TimedRun {
    fn steps_per_sec(&self) -> f64 {
        f64::from(self.steps) / self.seconds.max(f64::MIN_POSITIVE)
    }

    /// Trains `trainer` to `last_step`, adding the turn's time, steps and host costs to this
    /// run; returns the kernel dispatches it recorded, the partial-mask filter's left out.
    fn train_turn(
        &mut self,
        ctx: &GpuContext,
        trainer: &mut Trainer,
        last_step: u32,
    ) -> anyhow::Result<u64> {
        let first_step = trainer.step();
        let before = segsplat_gpu::dispatches_on_this_thread();
        let filter_before = trainer.partial_filter_cost().dispatches;
        let host_before = ctx.host_costs.reading_on_this_thread();
        let started = std::time::Instant::now();
        // Ends on a read-back, so the turn's GPU work is done when the clock stops.
        let progress = trainer.run_until(last_step, |_| true)?;
        self.seconds += started.elapsed().as_secs_f64();
        self.host
            .add(&ctx.host_costs.reading_on_this_thread().since(&host_before));
        self.steps += progress.step - first_step;
        let filter = trainer.partial_filter_cost().dispatches - filter_before;
        Ok(segsplat_gpu::dispatches_on_this_thread() - before - filter)
    }

    /// The host's side of a step, per step.
    fn host_report(&self) -> HostCostReport {
        let steps = f64::from(self.steps.max(1));
        let waited = self.host.wait_seconds().min(self.seconds);
        let submitted = self.host.submit_seconds().min(self.seconds - waited);
        HostCostReport {
            bytes_read_back_per_step: self.host.bytes_read_back as f64 / steps,
            read_backs_per_step: self.host.read_backs as f64 / steps,
            host_ms_per_step: (self.seconds - waited - submitted) * 1e3 / steps,
            wait_ms_per_step: waited * 1e3 / steps,
            submit_ms_per_step: submitted * 1e3 / steps,
            finish_ms_per_step: self.host.finish_seconds() * 1e3 / steps,
            bind_groups_created_per_step: self.host.bind_groups_created as f64 / steps,
            buffers_created_per_step: self.host.buffers_created as f64 / steps,
            compute_passes_per_step: self.host.compute_passes as f64 / steps,
        }
    }
}

/// Per training step: what the host read back, and its time outside the device's work
/// (encoding, progress, densification on the CPU), waiting for the device, and inside queue
/// submissions. A GPU's queue returns from a submission at once and the waits hold its
/// arithmetic; lavapipe's queue runs the work inside the submission, so there the submit
/// milliseconds hold it. Either way `host_ms_per_step` is the host's own share.
#[derive(Debug, Clone, Copy, Serialize)]
struct HostCostReport {
    bytes_read_back_per_step: f64,
    read_backs_per_step: f64,
    host_ms_per_step: f64,
    wait_ms_per_step: f64,
    submit_ms_per_step: f64,
    /// Of `host_ms_per_step`, the time in wgpu's `finish` of the step's encoders, where wgpu 30
    /// checks the recorded commands, works out their barriers and records the backend's
    /// commands (on Vulkan the driver's `vkCmd*`): what is left of the host's share is
    /// segsplat's own recording and wgpu's argument capture.
    finish_ms_per_step: f64,
    /// Bind groups made a step (the rest come from the cache; see docs/engine.md).
    bind_groups_created_per_step: f64,
    /// Buffers made a step for kernel parameters or slot tables (0 in a steady step).
    buffers_created_per_step: f64,
    /// Compute passes recorded a step: consecutive dispatches share one (`segsplat_gpu::Encoder`),
    /// so this is far below `dispatches_per_step`.
    compute_passes_per_step: f64,
}

/// Trains each of `trainers` to its last step, timing each. With more than one they take turns
/// of [`INTERLEAVED_STEPS`] steps, each turn waited for to its end, so a change in the machine's
/// speed (other processes, a shared host) falls on every trainer alike instead of on whichever
/// ran in those seconds: the step-time ratio of `--object-loss` comes from this.
fn timed_runs(ctx: &GpuContext, trainers: &mut [&mut Trainer]) -> anyhow::Result<Vec<TimedRun>> {
    let turn = if trainers.len() > 1 {
        INTERLEAVED_STEPS
    } else {
        u32::MAX
    };
    let mut runs = vec![TimedRun::default(); trainers.len()];
    let mut dispatches = vec![0u64; trainers.len()];
    while trainers
        .iter()
        .any(|trainer| trainer.step() < trainer.end_step())
    {
        for ((trainer, run), dispatched) in trainers.iter_mut().zip(&mut runs).zip(&mut dispatches)
        {
            let first_step = trainer.step();
            if first_step >= trainer.end_step() {
                continue;
            }
            *dispatched += run.train_turn(ctx, trainer, first_step.saturating_add(turn))?;
        }
    }
    for (run, dispatched) in runs.iter_mut().zip(dispatches) {
        run.dispatches_per_step = dispatched as f64 / f64::from(run.steps.max(1));
    }
    Ok(runs)
}

/// The plain half of `--object-loss`: `config` without the object loss, from `model`.
fn plain_trainer(
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

/// `--profile-kernels`: GPU time per training step by kernel, averaged over `steps`, and how
/// full the host kept the GPU over `--busy-steps` steps before them.
#[derive(Serialize)]
struct KernelProfileReport {
    steps: u32,
    /// GPU milliseconds a step inside the kernels (each dispatch timed in a pass of its own).
    gpu_ms_per_step: f64,
    /// Wall time per step of the timeline's steps, from an idle device to an idle device.
    wall_ms_per_step: f64,
    /// Wall time per step of the kernel-timed steps: each timed dispatch has a pass of its own,
    /// which costs the host more than the shared pass of untimed steps.
    profiled_wall_ms_per_step: f64,
    /// The share of the GPU's timeline the steps' passes filled (issue 38's target is at least
    /// 0.9); `timeline` has the figures behind it.
    gpu_busy_fraction: f64,
    timeline: segsplat_gpu::BusySummary,
    kernels: Vec<KernelTime>,
}

/// Runs `busy_steps` more training steps with their passes timed and `steps` more with every
/// dispatch timed (`segsplat_gpu::measure_busy`), and averages per step.
fn profile_kernels(
    ctx: &GpuContext,
    trainer: &mut Trainer,
    steps: u32,
    busy_steps: u32,
) -> anyhow::Result<KernelProfileReport> {
    anyhow::ensure!(
        ctx.profiler.is_some(),
        "kernel profiling is not enabled on this GPU context"
    );
    let steps = steps.max(1);
    let busy_steps = busy_steps.max(1);
    let reading = segsplat_gpu::measure_busy(
        ctx,
        busy_steps,
        steps,
        |count| -> anyhow::Result<()> {
            for _ in 0..count {
                trainer.train_step()?;
            }
            Ok(())
        },
        anyhow::Error::from,
    )?
    .context(
        "more passes than the profiler holds: use fewer --profile-kernels or --busy-steps steps",
    )?;
    let timeline = reading.summary(busy_steps, steps);
    let per_step = |ms: f64| ms / f64::from(steps);
    Ok(KernelProfileReport {
        steps,
        gpu_ms_per_step: timeline.kernel_ms_per_step,
        wall_ms_per_step: timeline.wall_ms_per_step,
        profiled_wall_ms_per_step: per_step(reading.profiled_wall_ms),
        gpu_busy_fraction: timeline.gpu_busy_fraction,
        timeline,
        kernels: reading
            .profile
            .kernels
            .into_iter()
            .map(|time| KernelTime {
                ms: per_step(time.ms),
                ..time
            })
            .collect(),
    })
}

/// The field `--deformation` trains: the shape a job gets on this adapter, resized by the flags.
fn deformation_config(args: &BenchArgs, software: bool) -> DeformationConfig {
    let mut field = FieldShape::for_adapter(software);
    if let Some(depth) = args.field_depth {
        field.depth = depth;
        // The released code joins the input again after layer D // 2; the kernels cannot join
        // it after layer 1, so fields of depth 2 or 3 have no skip.
        field.skip_after = if depth >= 4 { depth / 2 } else { 0 };
    }
    if let Some(width) = args.field_width {
        field.width = width;
    }
    DeformationConfig {
        field: Some(field),
        warm_up_steps: Some(0),
        ..DeformationConfig::default()
    }
}

/// A trainer for `config` (with the object loss when asked), and its object-loss report.
fn bench_trainer(
    ctx: &segsplat_gpu::GpuContext,
    scene: &Scene,
    config: TrainConfig,
    initial: Option<GaussianModel>,
    args: &BenchArgs,
) -> anyhow::Result<(Trainer, Option<ObjectLossReport>)> {
    if args.object_loss {
        let (trainer, report) = object_loss_trainer(
            ctx,
            scene,
            config,
            initial,
            args.objects_per_level,
            args.separate_object_renders,
        )?;
        Ok((trainer, Some(report)))
    } else {
        Ok((Trainer::new(ctx, scene, config, initial)?, None))
    }
}

/// The static half of `--deformation`: trains `config` without the field (same Gaussians),
/// returning (steps/s, seconds, held-out PSNR). Its trainer is dropped before the dynamic run
/// so the two never hold memory at once.
fn static_baseline(
    ctx: &segsplat_gpu::GpuContext,
    scene: &Scene,
    config: &TrainConfig,
    initial: Option<GaussianModel>,
    args: &BenchArgs,
) -> anyhow::Result<(f64, f64, f64)> {
    let config = TrainConfig {
        deformation: None,
        ..config.clone()
    };
    let (mut trainer, _) = bench_trainer(ctx, scene, config, initial, args)?;
    // The same warm-up before training as the dynamic run gets, so neither pays first-use costs
    // (intersection buffers sized by the first renders) inside its timed loop.
    trainer.time_passes(args.timing_repeats)?;
    let progress = trainer.run(|_| true)?;
    let eval = trainer.evaluate()?;
    Ok((progress.steps_per_sec, progress.elapsed_secs, eval.psnr))
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    let mut scene = super::open_scene(&args.dataset)?;
    let mut ctx = if args.noop_device {
        GpuContext::new_noop().context("cannot open the no-op device")?
    } else {
        super::open_gpu()?
    };
    if args.profile_kernels.is_some() {
        ctx.enable_kernel_profiling()?;
    }
    let mut config = TrainConfig {
        steps: args.steps,
        max_resolution: Some(args.max_resolution),
        eval_split_every: args.eval_split_every,
        seed: args.seed,
        ..base_train_config(&args)?
    };
    let initial = match (&args.init_ply, args.init_random) {
        (Some(path), _) => Some(
            read_ply_file(path)
                .with_context(|| format!("cannot read {}", path.display()))?
                .model,
        ),
        (None, Some(count)) => Some(random_model_in_points_bounds(&mut scene, count, args.seed)),
        (None, None) => None,
    };
    if args.no_densify || args.noop_device {
        config.densify_until = Some(0);
    }
    if args.converge {
        config
            .stop_when_converged
            .get_or_insert_with(ConvergenceStop::default);
    }
    let baseline = if args.deformation {
        config.deformation = Some(deformation_config(&args, ctx.report.is_software));
        config.validate()?;
        Some(static_baseline(
            &ctx,
            &scene,
            &config,
            initial.clone(),
            &args,
        )?)
    } else {
        None
    };
    let (mut trainer, object_loss) = bench_trainer(&ctx, &scene, config.clone(), initial, &args)?;
    let mut plain = match object_loss {
        Some(_) => Some(plain_trainer(
            &ctx,
            &scene,
            &config,
            trainer.model()?,
            args.timing_repeats,
        )?),
        None => None,
    };
    let gaussians_start = trainer.gaussian_count();
    let (forward_ms_start, backward_ms_start) = trainer.time_passes(args.timing_repeats)?;
    let mut curve = None;
    let (run, plain_run) = match plain.as_mut() {
        Some(plain) => match timed_runs(&ctx, &mut [&mut trainer, plain])?[..] {
            [run, plain_run] => (run, Some((plain, plain_run))),
            _ => anyhow::bail!("two timed runs expected"),
        },
        None => match args.eval_every {
            Some(every) => {
                let (run, points) = curve::run_with_curve(&ctx, &mut trainer, every)?;
                curve = Some(points);
                (run, None)
            }
            None => (timed_runs(&ctx, &mut [&mut trainer])?[0], None),
        },
    };
    let filter = trainer.partial_filter_cost();
    let partial_filter_seconds = filter.seconds;
    let plain_baseline = match plain_run {
        Some((plain, plain_run)) => {
            let with_filter = plain_run.steps_per_sec() / run.steps_per_sec();
            let step_share = (run.seconds - partial_filter_seconds) / run.seconds;
            Some(PlainBaselineReport {
                gaussians_start,
                steps_per_sec: plain_run.steps_per_sec(),
                dispatches_per_step: plain_run.dispatches_per_step,
                psnr: plain.evaluate()?.psnr,
                step_time_ratio: with_filter * step_share,
                step_time_ratio_with_filter: with_filter,
                partial_filter_seconds,
                partial_filter_dispatches: filter.dispatches,
                partial_filter: trainer.partial_filter_report().cloned(),
                dispatch_ratio: run.dispatches_per_step / plain_run.dispatches_per_step.max(1.0),
                kernel_profile: match args.profile_kernels {
                    Some(steps) => Some(profile_kernels(&ctx, plain, steps, args.busy_steps)?),
                    None => None,
                },
            })
        }
        _ => None,
    };
    let (forward_ms_end, backward_ms_end) = trainer.time_passes(args.timing_repeats)?;
    let field_timing = trainer.time_deformation(args.timing_repeats)?;
    let eval = trainer.evaluate()?;
    let kernel_profile = match args.profile_kernels {
        Some(steps) => Some(profile_kernels(&ctx, &mut trainer, steps, args.busy_steps)?),
        None => None,
    };
    let deformation = match (baseline, trainer.deformation_shape(), field_timing) {
        (
            Some((static_steps_per_sec, static_train_seconds, static_psnr)),
            Some((field, parameters)),
            Some((field_forward_ms, field_backward_ms)),
        ) => {
            let mut times: Vec<f32> = trainer.views().train.iter().map(|v| v.time).collect();
            times.sort_by(f32::total_cmp);
            times.dedup();
            let (forward, backward) = field.flops_per_gaussian();
            let field_gflop_per_step =
                (forward + backward) as f64 * trainer.gaussian_count() as f64 / 1e9;
            let field_gflops =
                field_gflop_per_step / ((field_forward_ms + field_backward_ms) / 1e3);
            let kernel = GemmKernel::for_adapter(&ctx);
            let matmul = measure_matmul(&ctx, kernel, 16_384, field.width, args.timing_repeats)?;
            Some(DeformationReport {
                field,
                parameters,
                training_times: times.len(),
                steps_per_sec: run.steps_per_sec(),
                train_seconds: run.seconds,
                static_steps_per_sec,
                static_train_seconds,
                static_psnr,
                step_time_ratio: static_steps_per_sec / run.steps_per_sec(),
                field_forward_ms,
                field_backward_ms,
                gemm_kernel: kernel.name().to_string(),
                field_gflop_per_step,
                field_gflops,
                field_rate_fraction: field_gflops / matmul.gflops,
                matmul,
            })
        }
        _ => None,
    };
    let [image_width, image_height] = trainer.views().max_size();
    let report = BenchReport {
        adapter: ctx.report.name.clone(),
        backend: ctx.report.backend.clone(),
        image_width,
        image_height,
        train_views: trainer.views().train.len(),
        test_views: trainer.views().test.len(),
        steps: trainer.step(),
        gaussians_start,
        gaussians_end: trainer.gaussian_count(),
        gaussian_budget: trainer.gaussian_budget(),
        forward_ms_start,
        forward_ms_end,
        backward_ms_start,
        backward_ms_end,
        steps_per_sec: run.steps_per_sec(),
        dispatches_per_step: run.dispatches_per_step,
        host: run.host_report(),
        train_seconds: run.seconds,
        psnr: eval.psnr,
        ssim: eval.ssim,
        worst_psnr: eval.worst_psnr,
        peak_resident_mib: super::peak_resident_mib(),
        object_loss,
        plain_baseline,
        deformation,
        kernel_profile,
        curve,
        converged_at: trainer.converged_at(),
        fit_checks: trainer.fit_checks().to_vec(),
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    Ok(())
}
