//! What the training job kinds share: failure classification, progress reports, checkpointed
//! training that honours cancel and shutdown at step boundaries.

use std::sync::Arc;

use super::stop_aware::StopSignal;
use super::trainer_setup::KernelsCompiledAhead;
use crate::job_kinds::checkpoint_writer::CheckpointWriter;
pub use crate::job_kinds::stage_cadence::{HeldOutPoint, StageCadence};
use crate::jobs::{JobContext, JobFailure, Progress};
use segsplat_engine::GaussianModel;
use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::model::ModelError;
use segsplat_engine::train::{
    ConvergedAt, EvalReport, TrainError, TrainProgress, Trainer, TrainerMeta,
};
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

/// Records an `undistorted` job event and logs it when the scene has cameras with lens
/// distortion: their frames are undistorted to pinhole cameras as they load (model,
/// coefficients and sizes in the event's `lenses`).
pub fn note_undistortion(ctx: &JobContext, scene: &segsplat_scene::Scene) {
    let lenses = segsplat_scene::distortion::undistorted_lenses(scene);
    if lenses.is_empty() {
        return;
    }
    let described: Vec<String> = lenses
        .iter()
        .map(segsplat_scene::distortion::describe_lens)
        .collect();
    let message = format!(
        "lens distortion detected; frames undistorted to pinhole cameras: {}",
        described.join("; ")
    );
    tracing::info!(job = %ctx.job_id, "{message}");
    let lenses = serde_json::to_value(&lenses).unwrap_or_default();
    if let Err(error) = ctx.progress.undistorted_blocking("load", &message, &lenses) {
        tracing::warn!(%error, "undistortion event not recorded");
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

/// Records the settings the job runs with, resolved from the scene, in the job and as a
/// `settings` event (`GET /v1/jobs/{id}` shows them as `settings`, beside the `config` it was
/// created with). A store that cannot take them is logged: the job runs all the same.
pub fn record_settings(ctx: &JobContext, settings: &impl Serialize) {
    // Through text, so an f32 reads as written (0.0007, not its f64 widening), as in
    // metrics.json.
    let recorded = serde_json::to_vec(settings)
        .and_then(|text| serde_json::from_slice::<serde_json::Value>(&text))
        .map_err(|error| error.to_string())
        .and_then(|value| {
            ctx.progress
                .settings_blocking(&value)
                .map_err(|error| error.to_string())
        });
    if let Err(error) = recorded {
        tracing::warn!(job = %ctx.job_id, %error, "cannot record the job's settings");
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
    /// Wall seconds the step loop spent on checkpoints (inside `seconds`): recording and
    /// submitting the snapshot's GPU copies, and waiting for the writer when a checkpoint came
    /// before the last was stored.
    pub checkpoint_seconds: f64,
    /// Seconds the checkpoint writer spent waiting for the snapshots' copies, reading them,
    /// encoding and storing, beside the step loop.
    #[serde(default)]
    pub checkpoint_write_seconds: f64,
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
    /// progress, densification's re-layout on the CPU, the partial-mask filter's host side and
    /// the busy sample's).
    pub host_ms_per_step: f64,
    /// Wall seconds of the partial-mask filter's pass (inside `seconds`, and its host side
    /// inside `host_ms_per_step`): it renders every (object, view) pair once, late in the
    /// stage, and reads the renders back.
    #[serde(default)]
    pub partial_filter_seconds: f64,
    /// Milliseconds a step the host waited for the GPU (read-backs, waits).
    pub wait_ms_per_step: f64,
    /// Milliseconds a step inside queue submissions (a software adapter runs the work there;
    /// a GPU's driver may hold a submission until earlier ones drain, so on a GPU this is
    /// partly a wait too).
    #[serde(default)]
    pub submit_ms_per_step: f64,
    /// Of `host_ms_per_step`, milliseconds a step in wgpu's `finish` of the step's encoders
    /// (its checks and barriers, and the backend's recording: Vulkan's `vkCmd*`).
    #[serde(default)]
    pub finish_ms_per_step: f64,
    /// Bind groups created a step (0 once every view has been seen: they are cached).
    #[serde(default)]
    pub bind_groups_created_per_step: f64,
    /// Buffers created a step on paths that should create none (0 in steady training).
    #[serde(default)]
    pub buffers_created_per_step: f64,
    /// Compute passes recorded a step: consecutive dispatches share one
    /// (`segsplat_gpu::Encoder`), so this is far below `dispatches_per_step`.
    #[serde(default)]
    pub compute_passes_per_step: f64,
    /// Share of the GPU's timeline its passes filled over a sample of steps in the middle of the
    /// stage (`segsplat_gpu::measure_busy`, `gpu_timeline.timeline_steps` of them): whether the
    /// host kept the GPU fed. Absent where the adapter has no timestamp queries or the stage was
    /// too short to sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpu_busy_fraction: Option<f64>,
    /// The sample behind `gpu_busy_fraction`: the GPU's milliseconds a step inside the step's
    /// passes, idle between them, and inside its kernels alone (`segsplat_gpu::BusySummary`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpu_timeline: Option<segsplat_gpu::BusySummary>,
    /// The deformation field's GEMM kernel (`tiled`, `rows`, `broadcast`: docs/engine.md), for
    /// a dynamic scene.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gemm_kernel: Option<String>,
    /// GPU milliseconds a step spent in the deformation field's passes (its GEMMs, reductions,
    /// encoding and warp; not its Adam step), from the sample's steps with every dispatch timed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field_gpu_ms_per_step: Option<f64>,
    /// `field_gpu_ms_per_step` over the sampled steps' whole GPU time: the field's share.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field_gpu_fraction: Option<f64>,
    /// Wall seconds of building the trainer before the stage (the initial model, the views'
    /// images and masks on the GPU, the kernels), outside `seconds`: what a job waits between
    /// its masks and its first step.
    #[serde(default)]
    pub setup_seconds: f64,
    /// Kernels the setup compiled, the seconds those compiles took (inside `setup_seconds`),
    /// and the kernels it reused instead: a worker's context keeps every kernel it compiled
    /// (`segsplat_gpu::kernel_cache`), and a job compiles its trainer's kernels while it makes
    /// its masks (`kernels_compiled_ahead`), so the setup itself should compile none.
    #[serde(default)]
    pub setup_kernels_compiled: u64,
    #[serde(default)]
    pub setup_kernel_compile_seconds: f64,
    #[serde(default)]
    pub setup_kernels_reused: u64,
    /// Kernels compiled on another thread before the setup (while the masks were made or the
    /// scene loaded), and the seconds that took there; absent when it did not run or failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernels_compiled_ahead: Option<KernelsCompiledAhead>,
    /// Training renders clamped to the intersection capacity, which grows a few steps behind
    /// the renders' peak (`Trainer::clamped_renders`): steps whose images and gradients dropped
    /// tile entries. 0 when the capacity kept up.
    #[serde(default)]
    pub clamped_renders: u64,
    /// Where the convergence stop ended training before its steps (a job that left `steps`
    /// out), and the check views' fit at every check: (step, mean PSNR).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub converged_at: Option<ConvergedAt>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fit_checks: Vec<(u32, f64)>,
    /// Held-out quality every `held_out_every` steps of this attempt (a job's config key; empty
    /// when it is 0): how the scene's quality moved against the training time the user waited.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held_out_curve: Vec<HeldOutPoint>,
    /// Wall seconds of those evaluations (inside `seconds`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub held_out_curve_seconds: f64,
}

fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

/// Steps run with every dispatch timed, for the GPU's time by kernel (the deformation field's
/// share): few enough for the profiler's 2048 passes at object-loss steps.
pub const BUSY_SAMPLE_STEPS: u32 = 5;

/// The most steps run with the shared passes timed, for [`TrainingStageReport::gpu_busy_fraction`]:
/// long enough that a densification step or a slow report in it weighs as it does in the stage.
/// A short stage samples a quarter of its steps (at least [`BUSY_SAMPLE_STEPS`]).
pub const BUSY_TIMELINE_STEPS: u32 = 100;

/// Trains to the configured end, saving a checkpoint named `checkpoint_name` every
/// `cadence.checkpoint_every` steps (0 = only at the end), evaluating the held-out views every
/// `cadence.held_out_every` (0 = never here), and stopping at the next report when the job is
/// cancelled or the service shuts down. Returns how this attempt's training went.
///
/// The step loop takes each checkpoint's snapshot (GPU copies of the trainer's state, no
/// read-back) and hands it to a [`CheckpointWriter`] thread, which reads the copies back,
/// encodes and stores them while training goes on; a store
/// that is unreachable skips that checkpoint with a `warning` job event and the next one tries
/// again (a crash meanwhile costs the steps since the last stored one, as always).
pub fn train_with_checkpoints(
    ctx: &JobContext,
    trainer: &mut Trainer,
    checkpoint_name: &str,
    cadence: StageCadence,
) -> Result<TrainingStageReport, JobFailure> {
    if trainer.step() == 0 {
        warn_about_schedule(ctx, trainer);
    }
    std::thread::scope(|scope| {
        let mut writer = CheckpointWriter::start(scope, ctx, checkpoint_name);
        train_stage(ctx, trainer, cadence, &mut writer)
            .and_then(|report| finish_writes(report, writer))
    })
}

/// Waits for the last checkpoint to be stored, counting the wait as the step loop's.
fn finish_writes(
    mut report: TrainingStageReport,
    writer: CheckpointWriter<'_>,
) -> Result<TrainingStageReport, JobFailure> {
    let waited = std::time::Instant::now();
    report.checkpoint_write_seconds = writer.finish()?;
    let waited = waited.elapsed().as_secs_f64();
    report.seconds += waited;
    report.checkpoint_seconds += waited;
    report.job_overhead_ratio = report.seconds
        / (report.seconds
            - report.checkpoint_seconds
            - report.report_seconds
            - report.held_out_curve_seconds)
            .max(1e-9);
    Ok(report)
}

/// The training loop of [`train_with_checkpoints`], handing snapshots to `writer`.
fn train_stage(
    ctx: &JobContext,
    trainer: &mut Trainer,
    cadence: StageCadence,
    writer: &mut CheckpointWriter<'_>,
) -> Result<TrainingStageReport, JobFailure> {
    let total = trainer.config().steps;
    let gpu = trainer.gpu().clone();
    let first_step = trainer.step();
    let filter_before = trainer.partial_filter_cost().seconds;
    let clamped_before = trainer.clamped_renders();
    let dispatches_before = segsplat_gpu::dispatches_on_this_thread();
    let host_before = gpu.host_costs.reading_on_this_thread();
    let started = std::time::Instant::now();
    let mut checkpoint_seconds = 0.0;
    let mut report_seconds = 0.0;
    let mut held_out_curve = Vec::new();
    let mut held_out_curve_seconds = 0.0;
    // Host costs of the checkpoints and evaluations, which the per-step figures leave out.
    let mut outside_steps_host = HostCostReading::default();
    // The busy sample (its passes timed, then its dispatches) starts halfway through what this
    // attempt trains, past the first steps' allocations and cache fills.
    let timeline_steps = ((total - first_step) / 4).clamp(BUSY_SAMPLE_STEPS, BUSY_TIMELINE_STEPS);
    let mut busy_sample_at = (gpu.profiler.is_some() && total - first_step > 4 * BUSY_SAMPLE_STEPS)
        .then(|| first_step + (total - first_step) / 2);
    let mut busy_sample = None;
    // The stage begins now, not at its first report (25 steps in: minutes, with a deformation
    // field on a CPU adapter). A client that times the stages from their first events (the
    // console, scripts/demo.sh) counted those minutes as the stage before.
    report(
        ctx,
        "train",
        first_step as u64,
        total as u64,
        &[("gaussians", trainer.gaussian_count() as f64)],
    );
    // Heard inside a step's long passes (the partial-mask filter), not only between reports.
    let stop = StopSignal::of(ctx);
    trainer.set_stop_check(Arc::new(move || stop.requested()));
    while trainer.step() < trainer.end_step() {
        let next_checkpoint = cadence.next_checkpoint(trainer.step(), total);
        let next_held_out = cadence.next_held_out(trainer.step(), total);
        let next_stop = next_checkpoint.min(next_held_out);
        let mut run_to = |trainer: &mut Trainer, last_step: u32| {
            trainer
                .run_until(last_step, |progress| {
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
                })
        };
        if let Some(at) = busy_sample_at.filter(|&at| at < next_stop) {
            // Both halves inside this stretch, so the sample never runs past a checkpoint or a
            // held-out point; a stretch too short hands it on to the next.
            // The timeline's steps shrink to what the stretch holds.
            if at + 2 * BUSY_SAMPLE_STEPS <= next_stop {
                busy_sample_at = None;
                run_to(trainer, at)?;
                ctx.stop_requested()?;
                let timeline_steps = timeline_steps.min(next_stop - at - BUSY_SAMPLE_STEPS);
                busy_sample = sample_gpu_busy(&gpu, trainer, timeline_steps, |trainer, last| {
                    run_to(trainer, last).map(|_| ())
                })?;
            } else {
                busy_sample_at = Some(next_stop);
            }
        }
        run_to(trainer, next_stop)?;
        ctx.stop_requested()?;
        // No point at the end, which the job evaluates itself (also an end the convergence
        // stop brought forward).
        if trainer.step() == next_held_out && trainer.step() < trainer.end_step() {
            // The steps' work still queued on the device is training time: waited for here, not
            // inside the evaluation's read-back, whose seconds the later points leave out.
            gpu.wait_idle()
                .map_err(|error| train_failure(error.into()))?;
            // Taken before this evaluation, which later points leave out: taken after it, a
            // slow first evaluation made the next point's training time smaller than this one's.
            let train_seconds = started.elapsed().as_secs_f64()
                - checkpoint_seconds
                - report_seconds
                - held_out_curve_seconds;
            let evaluating = std::time::Instant::now();
            let host_at_eval = gpu.host_costs.reading_on_this_thread();
            let eval = trainer.evaluate().map_err(train_failure)?;
            outside_steps_host.add(&gpu.host_costs.reading_on_this_thread().since(&host_at_eval));
            // In the log as it happens: the curve reaches metrics.json only when the job ends,
            // and an operator watching a long job (or a comparison cut short) wants it now.
            tracing::info!(
                job = %ctx.job_id,
                step = trainer.step(),
                psnr = eval.psnr,
                ssim = eval.ssim,
                gaussians = trainer.gaussian_count(),
                "held-out point"
            );
            held_out_curve.push(HeldOutPoint {
                step: trainer.step(),
                train_seconds,
                gaussians: trainer.gaussian_count(),
                psnr: eval.psnr,
                ssim: eval.ssim,
            });
            held_out_curve_seconds += evaluating.elapsed().as_secs_f64();
        }
        if trainer.step() < next_checkpoint && trainer.step() < trainer.end_step() {
            continue;
        }
        let checkpoint_started = std::time::Instant::now();
        let host_at_checkpoint = gpu.host_costs.reading_on_this_thread();
        writer.write(trainer)?;
        checkpoint_seconds += checkpoint_started.elapsed().as_secs_f64();
        outside_steps_host.add(
            &gpu.host_costs
                .reading_on_this_thread()
                .since(&host_at_checkpoint),
        );
    }
    let seconds = started.elapsed().as_secs_f64();
    let host = gpu.host_costs.reading_on_this_thread().since(&host_before);
    let steps = trainer.step() - first_step;
    let per_step = |value: f64| value / f64::from(steps.max(1));
    let waited = host.wait_seconds() - outside_steps_host.wait_seconds();
    let submitted = host.submit_seconds() - outside_steps_host.submit_seconds();
    let field_sample = busy_sample.filter(|sample| sample.field_ms_per_step > 0.0);
    Ok(TrainingStageReport {
        seconds,
        steps,
        gaussian_budget: trainer.gaussian_budget(),
        checkpoint_seconds,
        checkpoint_write_seconds: 0.0,
        report_seconds,
        job_overhead_ratio: seconds
            / (seconds - checkpoint_seconds - report_seconds - held_out_curve_seconds).max(1e-9),
        dispatches_per_step: per_step(
            (segsplat_gpu::dispatches_on_this_thread() - dispatches_before) as f64,
        ),
        bytes_read_back_per_step: per_step(
            (host.bytes_read_back - outside_steps_host.bytes_read_back) as f64,
        ),
        host_ms_per_step: per_step(
            (seconds - checkpoint_seconds - held_out_curve_seconds - waited - submitted).max(0.0)
                * 1e3,
        ),
        wait_ms_per_step: per_step(waited.max(0.0) * 1e3),
        partial_filter_seconds: trainer.partial_filter_cost().seconds - filter_before,
        submit_ms_per_step: per_step(submitted.max(0.0) * 1e3),
        finish_ms_per_step: per_step(
            (host.finish_seconds() - outside_steps_host.finish_seconds()).max(0.0) * 1e3,
        ),
        bind_groups_created_per_step: per_step(
            (host.bind_groups_created - outside_steps_host.bind_groups_created) as f64,
        ),
        buffers_created_per_step: per_step(
            (host.buffers_created - outside_steps_host.buffers_created) as f64,
        ),
        compute_passes_per_step: per_step(
            (host.compute_passes - outside_steps_host.compute_passes) as f64,
        ),
        gpu_busy_fraction: busy_sample.map(|sample| sample.summary.gpu_busy_fraction),
        gpu_timeline: busy_sample.map(|sample| sample.summary),
        gemm_kernel: trainer
            .deformation_gemm_kernel()
            .map(|kernel| kernel.name().to_string()),
        field_gpu_ms_per_step: field_sample.map(|sample| sample.field_ms_per_step),
        field_gpu_fraction: field_sample.map(|sample| sample.field_fraction),
        setup_seconds: 0.0,
        setup_kernels_compiled: 0,
        setup_kernel_compile_seconds: 0.0,
        setup_kernels_reused: 0,
        kernels_compiled_ahead: None,
        clamped_renders: trainer.clamped_renders() - clamped_before,
        converged_at: trainer.converged_at(),
        fit_checks: trainer.fit_checks().to_vec(),
        held_out_curve,
        held_out_curve_seconds,
    })
}

/// What the timed steps of [`sample_gpu_busy`] show.
#[derive(Debug, Clone, Copy)]
struct BusySample {
    summary: segsplat_gpu::BusySummary,
    /// GPU milliseconds a step in the deformation field's passes (0 for a static scene).
    field_ms_per_step: f64,
    /// Those over the steps' whole GPU time.
    field_fraction: f64,
}

/// Whether a profiled kernel is one of the deformation field's passes (`deform/kernels.rs`
/// labels them `mlp_*` and `deform_*`).
fn is_field_kernel(label: &str) -> bool {
    label.starts_with("mlp_") || label.starts_with("deform_")
}

/// Trains `timeline_steps` steps with their passes timed and [`BUSY_SAMPLE_STEPS`] more with
/// every dispatch timed (`segsplat_gpu::measure_busy`) and returns how full the GPU's timeline
/// was, and the deformation field's share of the GPU's time; `None` when the profiler dropped
/// passes (the figures would be low).
fn sample_gpu_busy(
    gpu: &segsplat_gpu::GpuContext,
    trainer: &mut Trainer,
    timeline_steps: u32,
    mut run_to: impl FnMut(&mut Trainer, u32) -> Result<(), JobFailure>,
) -> Result<Option<BusySample>, JobFailure> {
    let end = trainer.config().steps;
    let reading = segsplat_gpu::measure_busy(
        gpu,
        timeline_steps,
        BUSY_SAMPLE_STEPS,
        |steps| {
            let last = (trainer.step() + steps).min(end);
            run_to(trainer, last)
        },
        retryable,
    )?;
    let Some(reading) = reading else {
        return Ok(None);
    };
    let field_ms: f64 = reading
        .profile
        .kernels
        .iter()
        .filter(|kernel| is_field_kernel(&kernel.kernel))
        .map(|kernel| kernel.ms)
        .sum();
    let steps = f64::from(BUSY_SAMPLE_STEPS);
    Ok(Some(BusySample {
        summary: reading.summary(timeline_steps, BUSY_SAMPLE_STEPS),
        field_ms_per_step: field_ms / steps,
        field_fraction: field_ms / reading.profile.total_ms.max(1e-9),
    }))
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
    let mut metrics = vec![
        ("psnr", held_out.psnr),
        ("ssim", held_out.ssim),
        ("worst_psnr", held_out.worst_psnr),
        ("gaussians", gaussians as f64),
    ];
    if let Some(frame) = held_out.worst_frame_index {
        metrics.push(("worst_frame_index", frame as f64));
    }
    report(ctx, "evaluate", 1, 1, &metrics);
}
