//! The 3DGS training loop on the GPU.
//!
//! One step records, into a single command buffer: zero gradients, forward render, fused L1+SSIM
//! loss, backward render, densification statistics, and one Adam update per parameter group. It
//! is submitted without waiting; nothing is read back inside a step. CPU round trips happen only
//! (a) every `sync_every` steps to read the loss and the renderer's intersection peak (capacity
//! growth), and (b) at densification (every 100 steps), which re-lays out every per-Gaussian
//! buffer in GPU kernels and reads back only counts (`crate::densify::gpu`).
//!
//! This file holds the step loop; each other concern has its own file under `trainer/`: the
//! starting Gaussians (`initial`), what it reports and records (`reports`) and its errors
//! (`error`), the Adam update (`adam_step`), densification within the Gaussian budget
//! (`densification`), checkpoints (`checkpointing`, and `checkpoint_snapshot` for jobs), timing
//! and evaluation (`measure`), the object loss (`object_step`, `object_separate`,
//! `partial_filter`) and the deformation field (`dynamics`).

mod adam_step;
mod checkpoint_snapshot;
mod checkpointing;
mod densification;
mod dynamics;
mod error;
mod fit_check;
mod initial;
mod intersection_sizing;
mod measure;
mod object_separate;
mod object_step;
mod partial_filter;
mod reports;
mod warm_kernels;

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Instant;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::adam::{Adam, AdamSettings};
use crate::densify::PruneGuard;
use crate::densify::gpu::GpuDensifier;
use crate::loss::{LossImages, LossOutputs, RenderLoss};
use crate::model::{
    GaussianModel, GaussianParameterBuffers, GpuGaussianGrads, GpuGaussians,
    max_gaussians_for_adapter,
};
use crate::render::{RenderOutput, Renderer};
use crate::schedule::scene_extent;
use crate::train::budget::scene_gaussian_budget;
use crate::train::config::TrainConfig;
use crate::train::densify_stats::DensifyAccumulators;
use crate::train::object_loss::{MAX_OBJECTS_PER_LEVEL, ObjectTargets, SkippedPair};
use crate::train::partial_filter_report::PartialFilterReport;
use crate::train::random_init::{camera_centres, has_sparse_points};
use crate::train::schedule::{DeformationSchedule, SPARSE_CAPTURE_VIEWS, TrainSchedule};
use crate::train::views::Views;
use crate::{ObjectFilter, RenderSettings};
use segsplat_gpu::GpuContext;
use segsplat_gpu::deferred_read::DeferredRead;
use segsplat_scene::Scene;

pub use checkpoint_snapshot::PendingCheckpoint;
pub use error::TrainError;
pub use fit_check::ConvergedAt;
pub use initial::{
    initial_model, plain_initial_model, resolve_adapter_sized, resolve_random_init,
    scene_sized_random_init,
};
pub use reports::{EvalReport, PartialFilterCost, TrainProgress, TrainerMeta};

/// Steps between loss / capacity read-backs.
const SYNC_EVERY: u32 = 25;
/// Capacity headroom when (re)allocating Gaussian buffers, so densification rarely reallocates.
const CAPACITY_GROWTH: f64 = 1.5;
/// Loss slots per step: the full render, then up to `m` object renders at each of three levels.
const LOSS_SLOTS: u32 = 1 + 3 * MAX_OBJECTS_PER_LEVEL;

/// Asked inside the passes of a step that take long (the partial-mask filter); `true` stops.
pub type StopCheck = Arc<dyn Fn() -> bool + Send + Sync>;

pub struct Trainer {
    ctx: GpuContext,
    config: TrainConfig,
    /// When each stage runs (the config's values, or the recipe's scaled to its steps).
    schedule: TrainSchedule,
    views: Views,
    scene_extent: f32,
    gaussians: GpuGaussians,
    grads: GpuGaussianGrads,
    first_moments: GaussianParameterBuffers,
    second_moments: GaussianParameterBuffers,
    accumulators: DensifyAccumulators,
    densifier: GpuDensifier,
    renderer: Renderer,
    loss: RenderLoss,
    adam: Adam,
    grad_image: wgpu::Buffer,
    loss_values: wgpu::Buffer,
    /// The loss values' read-back for progress reports that must not wait.
    loss_read: DeferredRead,
    /// The newest loss values read back.
    last_losses: Option<Vec<f32>>,
    step: u32,
    rng: ChaCha8Rng,
    view_queue: Vec<usize>,
    prune_guard: Option<Box<dyn PruneGuard + Send>>,
    object_targets: Option<ObjectTargets>,
    /// Per level, the objects that owned Gaussians when the targets were set (see
    /// `ObjectLossConfig::only_objects_with_gaussians`).
    objects_with_gaussians: Option<[BTreeSet<u32>; 3]>,
    skipped_pairs: BTreeSet<SkippedPair>,
    /// What the partial-mask filter has cost (a one-off of the job, not a step).
    partial_filter_cost: PartialFilterCost,
    /// What the partial-mask filter found, once it has run.
    partial_filter_report: Option<PartialFilterReport>,
    started: Instant,
    steps_at_start: u32,
    /// The deformation field of a dynamic scene.
    dynamics: Option<dynamics::Dynamics>,
    /// Object renders one by one instead of batched (the reference path).
    separate_object_renders: bool,
    /// Whoever runs the trainer asks it to stop inside a long pass; see [`StopCheck`].
    stop_check: Option<StopCheck>,
    object_buffers: object_step::ObjectBuffers,
    /// The training resolution of the last step ([`TrainSchedule::resolution_divisor_at`]).
    resolution_divisor: Option<u32>,
    /// Whether the intersection capacity was fitted to a render before this trainer's first
    /// step ([`Self::size_intersections`]).
    intersections_sized: bool,
    /// Gaussians densification may grow to (the config's, or the scene's).
    gaussian_budget: usize,
    /// The convergence stop's checks and verdict (`config.stop_when_converged`).
    fit_check: fit_check::FitCheck,
}

/// Adam groups of 1 to 4 floats per Gaussian (means, scales, rotations, opacities, SH DC), which
/// the trainer steps in one dispatch, before the SH rest groups.
const SMALL_ADAM_GROUPS: usize = 5;

impl Trainer {
    /// Loads the views and uploads `model` (or the scene's initial model).
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        mut config: TrainConfig,
        model: Option<GaussianModel>,
    ) -> Result<Self, TrainError> {
        config.validate()?;
        if model.is_none() {
            resolve_random_init(&mut config, scene, ctx);
        }
        initial::resolve_field_shape(&mut config, ctx);
        let model = match model {
            Some(model) => model,
            None => plain_initial_model(scene, &config)?,
        };
        let mut schedule = TrainSchedule::resolve(&config);
        if !has_sparse_points(scene) {
            schedule = schedule.for_random_init();
        }
        let views = Views::load(
            ctx,
            scene,
            config.max_resolution,
            config.eval_split_every,
            schedule.coarse_halvings,
        )?;
        if views.train.len() < SPARSE_CAPTURE_VIEWS {
            schedule = schedule
                .for_sparse_capture(config.opacity_reset_interval, has_sparse_points(scene))
                .densify_within_passes(config.densify_until, views.train.len());
        }

        let [max_width, max_height] = views.max_size();
        let pixels = max_width as u64 * max_height as u64;
        let mut loss = RenderLoss::new(ctx)?;
        loss.reserve(ctx, max_width, max_height)?;
        let train_views = views.train.len();
        let training_pixels: u64 = views
            .train
            .iter()
            .map(|v| v.camera.pixel_count() as u64)
            .sum();
        let gaussian_budget = config
            .gaussian_budget
            .unwrap_or_else(|| scene_gaussian_budget(training_pixels, model.len()));
        let capacity = grown_capacity(ctx, model.len(), config.max_gaussians.min(gaussian_budget));
        let extent = scene_extent(&camera_centres(scene));
        let mut trainer = Self {
            gaussians: GpuGaussians::upload(ctx, &model, capacity)?,
            grads: GpuGaussianGrads::new(ctx, capacity)?,
            first_moments: GaussianParameterBuffers::new(ctx, "adam.m", capacity)?,
            second_moments: GaussianParameterBuffers::new(ctx, "adam.v", capacity)?,
            accumulators: DensifyAccumulators::new(ctx, capacity)?,
            densifier: GpuDensifier::new(ctx)?,
            renderer: Renderer::new(ctx)?,
            loss,
            adam: Adam::new(ctx, AdamSettings::default())?,
            grad_image: ctx.storage_buffer("grad image", pixels * 16)?,
            loss_values: ctx.storage_buffer("loss values", LOSS_SLOTS as u64 * 4)?,
            loss_read: DeferredRead::new(ctx, "loss values read-back", LOSS_SLOTS as u64 * 4),
            last_losses: None,
            ctx: ctx.clone(),
            schedule,
            config,
            views,
            scene_extent: extent,
            step: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
            view_queue: Vec::new(),
            prune_guard: None,
            object_targets: None,
            objects_with_gaussians: None,
            skipped_pairs: BTreeSet::new(),
            partial_filter_cost: PartialFilterCost::default(),
            partial_filter_report: None,
            started: Instant::now(),
            steps_at_start: 0,
            dynamics: None,
            separate_object_renders: false,
            stop_check: None,
            object_buffers: object_step::ObjectBuffers::default(),
            resolution_divisor: None,
            intersections_sized: false,
            gaussian_budget,
            fit_check: fit_check::FitCheck::default(),
        };
        trainer.rng = ChaCha8Rng::seed_from_u64(trainer.config.seed);
        if let Some(deformation) = trainer.config.deformation.clone() {
            // Its own seeded stream, so a dynamic config leaves the view order unchanged.
            let mut field_rng = ChaCha8Rng::seed_from_u64(trainer.config.seed ^ 0xdef0);
            let parameters = deformation
                .field_for(ctx.report.is_software)
                .initial_parameters(&mut field_rng);
            let times: Vec<f32> = trainer.views.train.iter().map(|v| v.time).collect();
            let schedule = trainer.schedule.deformation.unwrap_or_else(|| {
                DeformationSchedule::resolve(&deformation, trainer.schedule.laid_out_over)
            });
            trainer.dynamics = Some(dynamics::Dynamics::new(
                ctx,
                deformation,
                schedule,
                &parameters,
                capacity,
                times,
            )?);
        }
        debug_assert!(train_views > 0);
        Ok(trainer)
    }

    /// Lets the caller veto pruning (Segment then Splat's per-object persistence floor).
    pub fn set_prune_guard(&mut self, guard: Box<dyn PruneGuard + Send>) {
        self.prune_guard = Some(guard);
    }

    pub fn step(&self) -> u32 {
        self.step
    }

    /// The GPU context it trains on (its dispatch and host-cost counters).
    pub fn gpu(&self) -> &GpuContext {
        &self.ctx
    }

    pub fn gaussian_count(&self) -> usize {
        self.gaussians.count()
    }

    /// Renders of this trainer's steps clamped to the intersection capacity (they dropped tile
    /// entries, so their images and gradients were approximate), as of the last read of the
    /// renderer's peak: exact after [`Self::progress`]. The capacity follows the peak a few
    /// steps late, so a model or resolution that grows fast between two reads can clamp.
    pub fn clamped_renders(&self) -> u64 {
        self.renderer.clamped_renders()
    }

    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// When each stage of this job runs.
    pub fn schedule(&self) -> &TrainSchedule {
        &self.schedule
    }

    pub fn views(&self) -> &Views {
        &self.views
    }

    pub fn scene_extent(&self) -> f32 {
        self.scene_extent
    }

    /// The GPU scene (for renders outside training, e.g. masks).
    pub fn gaussians(&self) -> &GpuGaussians {
        &self.gaussians
    }

    /// Reads the current model back.
    pub fn model(&self) -> Result<GaussianModel, TrainError> {
        Ok(self.gaussians.download(&self.ctx)?)
    }

    fn next_view(&mut self) -> usize {
        if self.view_queue.is_empty() {
            self.view_queue = (0..self.views.train.len()).collect();
            self.view_queue.shuffle(&mut self.rng);
        }
        self.view_queue.pop().unwrap_or(0)
    }

    /// Runs one optimisation step. Returns the step number just finished (from 1).
    pub fn train_step(&mut self) -> Result<u32, TrainError> {
        let view_index = self.next_view();
        let step = self.step + 1;
        let sh_degree = self.schedule.sh_degree_at(self.step);
        let settings = RenderSettings {
            filter: ObjectFilter::All,
            background: self.config.background,
            sh_degree,
        };
        let ctx = &self.ctx;
        let mut encoder = segsplat_gpu::Encoder::new(ctx, "train step");
        self.grads.encode_zero(&mut encoder);
        encoder.clear_buffer(&self.loss_values, 0, None);
        let view_time = self.views.train[view_index].time;
        let time = self.training_time(view_time);
        let divisor = self.schedule.resolution_divisor_at(self.step);
        self.follow_resolution(divisor);
        if !self.intersections_sized {
            self.size_intersections(view_index, divisor, time, &settings)?;
        }
        self.apply_watched_peak(step)?;
        let output =
            self.encode_view_render(&mut encoder, view_index, divisor, time, &settings, true)?;
        // The object renders reuse the full render's projection and depth order, and add their
        // screen-space gradients to its own before the one projection backward of the step.
        self.encode_object_losses(&mut encoder, view_index, sh_degree, &output)?;
        self.encode_projection_backward(&mut encoder, &output)?;
        let ctx = &self.ctx;
        // The camera this step rendered through (the coarse one in coarse steps).
        let camera = output.camera;
        let count = self.gaussians.count() as u32;
        self.accumulators.encode_accumulate(
            ctx,
            &mut encoder,
            output.projected(),
            &self.grads.mean2d_abs,
            count,
            [camera.width, camera.height],
        );
        drop(output);
        self.encode_deform_backward_and_step(&mut encoder, step)?;
        self.encode_adam(&mut encoder, step, count, sh_degree)?;
        let peak_slot = self.request_watched_peak(&mut encoder, step);
        self.ctx.submit(encoder.finish());
        self.watched_peak_submitted(peak_slot);
        self.step = step;
        if self.schedule.densifies_at(step) || self.schedule.resets_opacity_at(step) {
            self.densify_and_reset(step)?;
        }
        if self.partial_filter_due(step) {
            self.filter_partial_masks(sh_degree)?;
        }
        Ok(step)
    }

    /// Records what a step renders of training view `view_index` at `time`: the deformation
    /// (dynamic scenes), the full render, and with `backward` its loss (loss slot 0) and the
    /// loss's screen-space gradients ([`Renderer::backward_screen`]); the caller records the
    /// projection backward that adds them into `self.grads`, after any object renders have
    /// added theirs. [`Self::train_step`] records its step with it and [`Self::time_passes`]
    /// times it, so the timed passes are the step's.
    fn encode_view_render(
        &mut self,
        encoder: &mut segsplat_gpu::Encoder,
        view_index: usize,
        divisor: u32,
        time: f32,
        settings: &RenderSettings,
        backward: bool,
    ) -> Result<RenderOutput, TrainError> {
        self.encode_deform_for_step(encoder, time)?;
        let ctx = &self.ctx;
        let (camera, target) = self.views.train[view_index].at_divisor(divisor);
        let camera = *camera;
        let scene = dynamics::render_view(&self.gaussians, &self.dynamics);
        let output = self
            .renderer
            .forward(ctx, encoder, scene, &camera, settings)?;
        if !backward {
            return Ok(output);
        }
        self.loss.encode(
            ctx,
            encoder,
            &LossImages {
                rendered: output.image(),
                rendered_index: 0,
                target,
                target_mask: None,
                width: camera.width,
                height: camera.height,
            },
            1.0,
            &LossOutputs {
                rendered_grad: &self.grad_image,
                grad_index: 0,
                loss_values: &self.loss_values,
                loss_slot: 0,
            },
        )?;
        self.renderer
            .backward_screen(ctx, encoder, &output, &self.grad_image)?;
        Ok(output)
    }

    /// Records the projection backward of `output` (the view render of
    /// [`Self::encode_view_render`]), adding its screen-space gradients, and those of any
    /// object renders batched on it, into `self.grads`.
    fn encode_projection_backward(
        &mut self,
        encoder: &mut segsplat_gpu::Encoder,
        output: &RenderOutput,
    ) -> Result<(), TrainError> {
        let scene = dynamics::render_view(&self.gaussians, &self.dynamics);
        self.renderer
            .backward_projection(&self.ctx, encoder, scene, output, &mut self.grads)?;
        Ok(())
    }

    /// Before the first step at a new training resolution: a finer one needs about
    /// `(old / new)^2` times the tile intersections, so the capacity grows by that at once
    /// instead of overflowing until the next sync notices.
    fn follow_resolution(&mut self, divisor: u32) {
        if let Some(previous) = self.resolution_divisor
            && divisor < previous
        {
            let finer = (previous / divisor.max(1)) as f64;
            self.renderer
                .grow_intersection_capacity(&self.ctx, finer * finer);
        }
        self.resolution_divisor = Some(divisor);
    }

    /// Trains until the configured `steps` are done; see [`Trainer::run_until`].
    pub fn run(
        &mut self,
        on_progress: impl FnMut(&TrainProgress) -> bool,
    ) -> Result<TrainProgress, TrainError> {
        self.run_until(self.config.steps, on_progress)
    }

    /// Trains until step `last_step` (capped at the configured steps), calling `on_progress`
    /// every [`SYNC_EVERY`] steps and at `last_step`; stops early when it returns `false`
    /// (cancel). Step rates in the reports count from this call. The reports between are read
    /// without waiting for the device ([`Self::progress_without_waiting`]); the last is exact.
    pub fn run_until(
        &mut self,
        last_step: u32,
        mut on_progress: impl FnMut(&TrainProgress) -> bool,
    ) -> Result<TrainProgress, TrainError> {
        let last_step = last_step.min(self.end_step());
        self.started = Instant::now();
        self.steps_at_start = self.step;
        while self.step < last_step {
            let step = self.train_step()?;
            // Checked on every step, the turn's last included: a caller's turns may end on
            // check steps.
            let converged = self.check_convergence(step)?;
            let last = step == last_step || converged;
            let progress = if last {
                self.progress()?
            } else if step % SYNC_EVERY == 0 {
                self.progress_without_waiting()?
            } else {
                continue;
            };
            // The last step's report is exact and final: no second read-back after it.
            if !on_progress(&progress) || last {
                return Ok(progress);
            }
        }
        self.progress()
    }

    /// Reads the latest loss and the renderer's intersection peak (a sync point).
    pub fn progress(&mut self) -> Result<TrainProgress, TrainError> {
        let clamped_before = self.renderer.clamped_renders();
        self.renderer.sync_capacity(&self.ctx)?;
        self.log_clamped_since(clamped_before);
        let losses: Vec<f32> = self.ctx.read_vec(&self.loss_values)?;
        self.last_losses = Some(losses);
        Ok(self.progress_from_last_losses())
    }

    /// Progress with the newest loss the device has delivered, and the intersection capacity
    /// grown for the newest peak, without draining the queue: both are requested now (copies
    /// behind the submitted steps) and read when the device gets there, so on a GPU the loss
    /// reported is a few steps old. Only the first report of a trainer waits, so that every
    /// report has a loss.
    fn progress_without_waiting(&mut self) -> Result<TrainProgress, TrainError> {
        let mut encoder = segsplat_gpu::Encoder::new(&self.ctx, "progress read-back");
        let loss_slot = self.loss_read.record(&mut encoder, &self.loss_values);
        let peak_slot = self.renderer.request_capacity_check(&mut encoder);
        self.ctx.submit_untimed(encoder.finish());
        if let Some(slot) = loss_slot {
            self.loss_read.after_submit(slot);
        }
        if let Some(slot) = peak_slot {
            self.renderer.capacity_check_submitted(slot);
        }
        self.apply_deferred_peak()?;
        let delivered = if self.last_losses.is_none() {
            self.loss_read.read_now(&self.ctx)?
        } else {
            self.loss_read.take(&self.ctx)?
        };
        if let Some(bytes) = delivered {
            self.last_losses = Some(bytemuck::pod_collect_to_vec(&bytes));
        }
        Ok(self.progress_from_last_losses())
    }

    /// Says in the log when a read found clamped renders (the step is the read's, up to a few
    /// dozen steps after the renders), which the run's reports only count.
    fn log_clamped_since(&self, before: u64) {
        let clamped = self.renderer.clamped_renders() - before;
        if clamped > 0 {
            tracing::debug!(
                step = self.step,
                clamped,
                capacity = self.renderer.intersection_capacity(),
                gaussians = self.gaussians.count(),
                "training renders clamped to the intersection capacity"
            );
        }
    }

    fn progress_from_last_losses(&self) -> TrainProgress {
        let losses = self.last_losses.as_deref().unwrap_or_default();
        let elapsed = self.started.elapsed().as_secs_f64();
        TrainProgress {
            step: self.step,
            total_steps: self.end_step(),
            loss: losses.first().copied().unwrap_or(f32::NAN),
            object_loss: losses.iter().skip(1).sum(),
            gaussians: self.gaussians.count(),
            elapsed_secs: elapsed,
            steps_per_sec: (self.step - self.steps_at_start) as f64 / elapsed.max(1e-9),
        }
    }

    /// Seeded randomness for callers that extend a step (object sampling).
    pub fn rng(&mut self) -> &mut impl Rng {
        &mut self.rng
    }
}

/// Buffer capacity for `count` Gaussians: headroom for densification, within the configured
/// maximum and what one storage binding of the adapter holds, never below `count` (a scene that
/// does not fit then fails with the buffer's name and size).
fn grown_capacity(ctx: &GpuContext, count: usize, max_gaussians: usize) -> usize {
    let ceiling = max_gaussians.min(max_gaussians_for_adapter(ctx));
    ((count as f64 * CAPACITY_GROWTH) as usize)
        .min(ceiling)
        .max(count)
}
