//! Dynamic scenes in the training loop: the deformation field moves the canonical Gaussians to
//! each view's time before its renders, and its backward pass runs once per step after every
//! render's gradients are in (so the object loss trains the field too).

use std::time::Instant;

use rand_distr::{Distribution, StandardNormal};

use super::{TrainError, Trainer};
use crate::deform::config::time_interval;
use crate::deform::{
    DeformationConfig, DeformationField, DeformationHeader, DeformedGeometry, FieldShape,
    StoredDeformation,
};
use crate::model::GaussianView;
use crate::train::schedule::DeformationSchedule;
use crate::{GaussianModel, GpuGaussians};
use segsplat_gpu::GpuContext;

/// The field, its deformed geometry and what the current step deformed.
pub(super) struct Dynamics {
    pub config: DeformationConfig,
    /// Its warm-up, learning-rate decay and time-noise steps for this job.
    pub schedule: DeformationSchedule,
    pub field: DeformationField,
    pub geometry: DeformedGeometry,
    /// Gap between distinct training times (scales the time noise).
    pub time_interval: f32,
    /// Time the geometry was last deformed to in this step, awaiting its backward pass.
    pub deformed_at: Option<f32>,
}

impl Dynamics {
    pub fn new(
        ctx: &GpuContext,
        config: DeformationConfig,
        schedule: DeformationSchedule,
        parameters: &[f32],
        capacity: usize,
        train_times: impl IntoIterator<Item = f32>,
    ) -> Result<Self, TrainError> {
        Ok(Self {
            field: DeformationField::new(
                ctx,
                config.field_for(ctx.report.is_software),
                parameters,
                config.chunk_gaussians,
            )?,
            geometry: DeformedGeometry::new(ctx, capacity)?,
            time_interval: time_interval(train_times),
            deformed_at: None,
            config,
            schedule,
        })
    }
}

/// What renders read: the deformed geometry once the field is active, else the canonical scene.
pub(super) fn render_view<'a>(
    gaussians: &'a GpuGaussians,
    dynamics: &'a Option<Dynamics>,
) -> GaussianView<'a> {
    match dynamics {
        Some(dynamics) if dynamics.deformed_at.is_some() => dynamics.geometry.view(gaussians),
        _ => gaussians.view(),
    }
}

/// Records the field's forward pass to `time` when it is active at `step` (and clears the
/// deformed state otherwise); renders recorded after it see the moved scene. A free function so
/// callers can hold other fields of the trainer meanwhile.
pub(super) fn deform_to(
    ctx: &GpuContext,
    step: u32,
    dynamics: &mut Option<Dynamics>,
    gaussians: &GpuGaussians,
    encoder: &mut segsplat_gpu::Encoder,
    time: f32,
) -> Result<(), TrainError> {
    let Some(dynamics) = dynamics.as_mut() else {
        return Ok(());
    };
    if !dynamics.schedule.active_at(step) {
        dynamics.deformed_at = None;
        return Ok(());
    }
    if dynamics.geometry.capacity() < gaussians.capacity() {
        dynamics.geometry = DeformedGeometry::new(ctx, gaussians.capacity())?;
    }
    dynamics
        .field
        .encode_forward(ctx, encoder, gaussians, &dynamics.geometry, time)?;
    dynamics.deformed_at = Some(time);
    Ok(())
}

impl Trainer {
    /// Starts a step's deformation: forgets the previous step's (the canonical Gaussians have
    /// moved since) and deforms to `time`.
    pub(super) fn encode_deform_for_step(
        &mut self,
        encoder: &mut segsplat_gpu::Encoder,
        time: f32,
    ) -> Result<(), TrainError> {
        if let Some(dynamics) = self.dynamics.as_mut() {
            dynamics.deformed_at = None;
        }
        deform_to(
            &self.ctx,
            self.step,
            &mut self.dynamics,
            &self.gaussians,
            encoder,
            time,
        )
    }

    /// The training time of a view this step: its frame time plus the annealed time noise.
    pub(super) fn training_time(&mut self, view_time: f32) -> f32 {
        let step = self.step;
        let Some(dynamics) = self.dynamics.as_ref() else {
            return view_time;
        };
        let sigma = dynamics
            .config
            .time_noise_at(step, dynamics.time_interval, &dynamics.schedule);
        if sigma <= 0.0 || !dynamics.schedule.active_at(step) {
            return view_time;
        }
        let noise: f32 = StandardNormal.sample(&mut self.rng);
        view_time + sigma * noise
    }

    /// Records the field's backward pass (turning the gradients of the deformed geometry into
    /// canonical ones) and its Adam step, when this step deformed the scene. Must follow every
    /// render of the step and precede the Gaussians' Adam step.
    pub(super) fn encode_deform_backward_and_step(
        &mut self,
        encoder: &mut segsplat_gpu::Encoder,
        adam_step: u32,
    ) -> Result<(), TrainError> {
        let step = self.step;
        let Some(dynamics) = self.dynamics.as_mut() else {
            return Ok(());
        };
        let Some(time) = dynamics.deformed_at else {
            return Ok(());
        };
        dynamics.field.encode_zero_grads(encoder);
        dynamics
            .field
            .encode_backward(&self.ctx, encoder, &self.gaussians, &self.grads, time)?;
        // The field's Adam counts its steps from its first active step, like a fresh optimiser.
        let field_step = adam_step
            .saturating_sub(dynamics.schedule.warm_up_steps)
            .max(1);
        let rate = dynamics.config.learning_rate_at(step, &dynamics.schedule)
            * self.schedule.polish_factor_at(step);
        dynamics
            .field
            .encode_adam(&self.ctx, encoder, &self.adam, rate, field_step)?;
        Ok(())
    }

    /// The deformation field's shape and parameter count, for a dynamic scene.
    pub fn deformation_shape(&self) -> Option<(FieldShape, usize)> {
        self.dynamics
            .as_ref()
            .map(|dynamics| (*dynamics.field.shape(), dynamics.field.parameter_count()))
    }

    /// The GEMM kernel the deformation field runs on, for a dynamic scene (a job's metrics say
    /// which one trained it).
    pub fn deformation_gemm_kernel(&self) -> Option<crate::deform::GemmKernel> {
        self.dynamics
            .as_ref()
            .map(|dynamics| dynamics.field.gemm_kernel())
    }

    /// Times the deformation field alone over every Gaussian, without changing the model: its
    /// forward pass (deformed geometry written), then its backward pass (weight gradients zeroed
    /// and recomputed from whatever the Gaussian gradients hold; their values do not change the
    /// cost), each submitted and waited for (wall clock, like [`Trainer::time_passes`]), at the
    /// training views' times in turn. Returns (forward ms, backward ms) averaged over `repeats`,
    /// or `None` for a static trainer. The field's Adam step is not included.
    pub fn time_deformation(&mut self, repeats: u32) -> Result<Option<(f64, f64)>, TrainError> {
        let ctx = self.ctx.clone();
        let Some(dynamics) = self.dynamics.as_mut() else {
            return Ok(None);
        };
        if dynamics.geometry.capacity() < self.gaussians.capacity() {
            dynamics.geometry = DeformedGeometry::new(&ctx, self.gaussians.capacity())?;
        }
        let (mut forward_secs, mut backward_secs) = (0.0, 0.0);
        for repeat in 0..repeats.max(1) {
            let time = self.views.train[repeat as usize % self.views.train.len()].time;
            let started = Instant::now();
            let mut encoder = segsplat_gpu::Encoder::new(&ctx, "timing deformation forward");
            dynamics.field.encode_forward(
                &ctx,
                &mut encoder,
                &self.gaussians,
                &dynamics.geometry,
                time,
            )?;
            ctx.submit(encoder.finish());
            ctx.wait_idle()?;
            forward_secs += started.elapsed().as_secs_f64();
            // The backward reuses the activations the forward left resident (as in a step).
            let started = Instant::now();
            let mut encoder = segsplat_gpu::Encoder::new(&ctx, "timing deformation backward");
            dynamics.field.encode_zero_grads(&mut encoder);
            dynamics.field.encode_backward(
                &ctx,
                &mut encoder,
                &self.gaussians,
                &self.grads,
                time,
            )?;
            ctx.submit(encoder.finish());
            ctx.wait_idle()?;
            backward_secs += started.elapsed().as_secs_f64();
        }
        // The next step deforms afresh; nothing of this timing may stand for its state.
        dynamics.deformed_at = None;
        let repeats = f64::from(repeats.max(1));
        Ok(Some((
            forward_secs / repeats * 1e3,
            backward_secs / repeats * 1e3,
        )))
    }

    /// The field's weights, for a dynamic scene (read back; waits for submitted work).
    pub fn deformation_parameters(&self) -> Result<Option<Vec<f32>>, TrainError> {
        match &self.dynamics {
            Some(dynamics) => Ok(Some(
                dynamics.field.read(&self.ctx, &dynamics.field.parameters)?,
            )),
            None => Ok(None),
        }
    }
}

impl Trainer {
    /// The scene as it is at `time`: the canonical model with the field's geometry at that time
    /// (the canonical model itself for a static scene). Reads back; waits for the GPU.
    pub fn model_at(&mut self, time: f32) -> Result<GaussianModel, TrainError> {
        let mut model = self.gaussians.download(&self.ctx)?;
        let Some(dynamics) = self.dynamics.as_mut() else {
            return Ok(model);
        };
        if dynamics.geometry.capacity() < self.gaussians.capacity() {
            dynamics.geometry = DeformedGeometry::new(&self.ctx, self.gaussians.capacity())?;
        }
        let mut encoder = segsplat_gpu::Encoder::new(&self.ctx, "deform for read-back");
        dynamics.field.encode_forward(
            &self.ctx,
            &mut encoder,
            &self.gaussians,
            &dynamics.geometry,
            time,
        )?;
        self.ctx.submit(encoder.finish());
        // The next step deforms afresh.
        dynamics.deformed_at = None;
        dynamics.geometry.read_into(&self.ctx, &mut model)?;
        Ok(model)
    }

    /// The deformation config of a dynamic scene.
    pub fn deformation_config(&self) -> Option<&DeformationConfig> {
        self.dynamics.as_ref().map(|d| &d.config)
    }
}

impl Trainer {
    /// The trained field as stored next to the canonical Gaussians, with the span of the scene's
    /// `times` (distinct, ascending); `None` for a static scene. Reads back.
    pub fn stored_deformation(
        &self,
        times: &[f32],
    ) -> Result<Option<StoredDeformation>, TrainError> {
        let (Some(config), Some(parameters)) =
            (self.deformation_config(), self.deformation_parameters()?)
        else {
            return Ok(None);
        };
        let first = times.first().copied().unwrap_or(0.0);
        Ok(Some(StoredDeformation {
            header: DeformationHeader {
                field: config.field_for(self.ctx.report.is_software),
                parameter_count: parameters.len(),
                time_range: [first, times.last().copied().unwrap_or(first)],
            },
            parameters,
        }))
    }
}
