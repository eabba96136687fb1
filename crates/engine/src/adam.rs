//! Adam on the GPU: one kernel over a flat f32 parameter array with its gradient and two moment
//! buffers. The trainer calls it once per parameter group (means, scales, ...) with that group's
//! learning rate, so per-parameter learning rates and the 3DGS schedules live in the trainer.
//!
//! Dense by default, exactly PyTorch's `Adam` (what 3DGS trains with): an element with a zero
//! gradient still decays its moments and moves by momentum. [`AdamSettings::skip_zero_gradients`]
//! leaves elements whose gradient is exactly zero untouched instead, an element-wise stand-in for
//! 3DGS's optional sparse Adam (which skips Gaussians outside the view: those get exactly zero
//! gradients in every element).

mod groups;

use segsplat_gpu::kernel::{wgsl_u32_constants, workgroups_2d};
use segsplat_gpu::{GpuContext, GpuError, Kernel};

const ADAM_STEP: &str = include_str!("adam_step.wgsl");
const ADAM_UPDATE: &str = include_str!("adam_update.wgsl");
/// Invocations per workgroup, one element each (prepended to `adam_step.wgsl`).
const ADAM_WORKGROUP: u32 = 256;

#[derive(Debug, thiserror::Error)]
pub enum AdamError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("Adam step needs {element_count} f32 in {what} but it holds {actual_bytes} bytes")]
    BufferTooSmall {
        what: &'static str,
        element_count: u32,
        actual_bytes: u64,
    },
    #[error("Adam step counts from 1, got step 0")]
    StepZero,
}

/// Adam's constants (3DGS: beta1 0.9, beta2 0.999, epsilon 1e-15).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamSettings {
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
    pub skip_zero_gradients: bool,
}

impl Default for AdamSettings {
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-15,
            skip_zero_gradients: false,
        }
    }
}

/// `AdamConstants` of `adam_update.wgsl`: what every group of a step shares.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct AdamConstants {
    inv_sqrt_bias_correction2: f32,
    beta1: f32,
    beta2: f32,
    one_minus_beta1: f32,
    one_minus_beta2: f32,
    epsilon: f32,
    skip_zero_gradients: u32,
    _pad: u32,
}

impl AdamConstants {
    /// The constants of step `step` (from 1) and its first bias correction, 1 - beta1^step,
    /// which each group's step size divides by (in f64).
    fn at_step(settings: &AdamSettings, step: u32) -> (Self, f64) {
        let bias_correction1 = 1.0 - settings.beta1.powf(f64::from(step));
        let bias_correction2 = 1.0 - settings.beta2.powf(f64::from(step));
        let constants = Self {
            inv_sqrt_bias_correction2: (1.0 / bias_correction2.sqrt()) as f32,
            beta1: settings.beta1 as f32,
            beta2: settings.beta2 as f32,
            one_minus_beta1: (1.0 - settings.beta1) as f32,
            one_minus_beta2: (1.0 - settings.beta2) as f32,
            epsilon: settings.epsilon as f32,
            skip_zero_gradients: u32::from(settings.skip_zero_gradients),
            _pad: 0,
        };
        (constants, bias_correction1)
    }
}

/// Uniform block of `adam_step.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct AdamParams {
    constants: AdamConstants,
    step_size: f32,
    element_count: u32,
    _pad: [u32; 2],
}

/// The buffers of one parameter group, each holding at least `element_count` f32.
#[derive(Debug, Clone, Copy)]
pub struct AdamBuffers<'a> {
    pub params: &'a wgpu::Buffer,
    pub grads: &'a wgpu::Buffer,
    pub first_moment: &'a wgpu::Buffer,
    pub second_moment: &'a wgpu::Buffer,
}

pub use groups::ADAM_GROUPS;

/// One parameter group's step: its buffers, how many elements, its learning rate.
#[derive(Debug, Clone, Copy)]
pub struct AdamGroup<'a> {
    pub buffers: AdamBuffers<'a>,
    pub element_count: u32,
    pub learning_rate: f32,
}

/// The Adam update kernels (see the module doc): one group per dispatch, and where the adapter
/// binds enough storage buffers, every group in one dispatch (`adam/groups.rs`).
#[derive(Debug)]
pub struct Adam {
    kernel: Kernel,
    groups_kernel: groups::AdamGroupsKernel,
    pub settings: AdamSettings,
}

impl Adam {
    pub fn new(ctx: &GpuContext, settings: AdamSettings) -> Result<Self, AdamError> {
        let constants = wgsl_u32_constants(&[("ADAM_WORKGROUP", ADAM_WORKGROUP)]);
        let kernel = Kernel::new(
            ctx,
            "adam_step",
            &[&constants, ADAM_UPDATE, ADAM_STEP],
            "adam_step",
            &[],
        )?;
        let groups_kernel = groups::AdamGroupsKernel::new(ctx)?;
        Ok(Self {
            kernel,
            groups_kernel,
            settings,
        })
    }

    /// Records Adam step number `step` of every group in `groups`, each with its own learning
    /// rate: the same updates as [`Self::encode_step`] per group, in one dispatch where the
    /// adapter allows it (2 to [`ADAM_GROUPS`] groups), else one dispatch per group. Invocation
    /// i steps element i of every group, so give one call groups of similar sizes.
    pub fn encode_steps(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        groups: &[AdamGroup<'_>],
        step: u32,
    ) -> Result<(), AdamError> {
        if step == 0 {
            return Err(AdamError::StepZero);
        }
        for group in groups {
            check_buffers(&group.buffers, group.element_count)?;
        }
        if self.groups_kernel.covers(groups.len()) {
            self.groups_kernel
                .encode(ctx, encoder, &self.settings, groups, step);
            return Ok(());
        }
        for group in groups {
            self.encode_step(
                ctx,
                encoder,
                &group.buffers,
                group.element_count,
                group.learning_rate,
                step,
            )?;
        }
        Ok(())
    }

    /// Records Adam step number `step` (from 1, for the bias corrections) over the first
    /// `element_count` elements. The learning rate and step travel in a uniform buffer made for
    /// this call, so several groups' steps recorded before one submit keep their own values (a
    /// shared buffer updated with `queue.write_buffer` would hold only the last) and nothing is
    /// read back.
    pub fn encode_step(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        buffers: &AdamBuffers<'_>,
        element_count: u32,
        learning_rate: f32,
        step: u32,
    ) -> Result<(), AdamError> {
        if step == 0 {
            return Err(AdamError::StepZero);
        }
        check_buffers(buffers, element_count)?;
        if element_count == 0 {
            return Ok(());
        }
        let (constants, bias_correction1) = AdamConstants::at_step(&self.settings, step);
        let params = AdamParams {
            constants,
            step_size: (f64::from(learning_rate) / bias_correction1) as f32,
            element_count,
            _pad: [0; 2],
        };
        let bind_group = self.kernel.bind_params(
            ctx,
            bytemuck::bytes_of(&params),
            &[
                buffers.params,
                buffers.grads,
                buffers.first_moment,
                buffers.second_moment,
            ],
        );
        let groups = element_count.div_ceil(ADAM_WORKGROUP);
        let grid = workgroups_2d(groups, ctx.limits.max_compute_workgroups_per_dimension);
        self.kernel.dispatch(encoder, &bind_group, grid);
        Ok(())
    }
}

/// Each buffer of `buffers` holds at least `element_count` f32.
fn check_buffers(buffers: &AdamBuffers<'_>, element_count: u32) -> Result<(), AdamError> {
    let needed_bytes = u64::from(element_count) * 4;
    for (what, buffer) in [
        ("params", buffers.params),
        ("grads", buffers.grads),
        ("first_moment", buffers.first_moment),
        ("second_moment", buffers.second_moment),
    ] {
        if buffer.size() < needed_bytes {
            return Err(AdamError::BufferTooSmall {
                what,
                element_count,
                actual_bytes: buffer.size(),
            });
        }
    }
    Ok(())
}
