//! `segsplat bench DIR`: trains plain 3DGS (or, with `--object-loss`, with the Segment-then-Splat
//! object loss on the dataset's own or classical masks) and reports speed and held-out quality as
//! one JSON object (see the README for figures measured with it). With `--deformation` it trains
//! the same Gaussians twice, as a static scene and with the deformation field, and reports what
//! the field costs per step.

mod curve;
pub mod matmul;
mod object_loss;
mod profile;
mod timing;

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
use segsplat_engine::train::{ConvergedAt, TrainConfig, Trainer};
use segsplat_gpu::GpuContext;
use segsplat_scene::Scene;
use segsplat_service::job_kinds::training::BUSY_TIMELINE_STEPS;
use serde::Serialize;

use object_loss::{ObjectLossReport, PlainBaselineReport, object_loss_trainer, plain_trainer};
use profile::{KernelProfileReport, profile_kernels};
use timing::{HostCostReport, TimedRun, timed_runs};

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
    /// Rows (Gaussians) of the GEMM measurement `--deformation` reports as `matmul` (the rate the
    /// field's is compared with). Fewer make it quicker where only the run matters, such as the
    /// synchronization validation's runs.
    #[arg(
        long,
        requires = "deformation",
        default_value_t = 16_384,
        value_parser = clap::value_parser!(u32).range(1..)
    )]
    pub matmul_rows: u32,
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
    /// Training renders clamped to the intersection capacity (`Trainer::clamped_renders`):
    /// steps whose images and gradients dropped tile entries.
    clamped_renders: u64,
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
    ctx: &GpuContext,
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
    ctx: &GpuContext,
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
    // The steps and the model the report's quality figures are of: the kernel profile below
    // trains more steps after them.
    let (trained_steps, gaussians_end) = (trainer.step(), trainer.gaussian_count());
    let clamped_renders = trainer.clamped_renders();
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
            let field_gflop_per_step = (forward + backward) as f64 * gaussians_end as f64 / 1e9;
            let field_gflops =
                field_gflop_per_step / ((field_forward_ms + field_backward_ms) / 1e3);
            let kernel = GemmKernel::for_adapter(&ctx);
            let matmul = measure_matmul(
                &ctx,
                kernel,
                args.matmul_rows,
                field.width,
                args.timing_repeats,
            )?;
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
        steps: trained_steps,
        gaussians_start,
        gaussians_end,
        gaussian_budget: trainer.gaussian_budget(),
        clamped_renders,
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
