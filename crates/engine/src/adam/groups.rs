//! Adam over several parameter groups in one dispatch (`adam_groups.wgsl`): invocation i steps
//! element i of every group that has one, so the groups of one dispatch should have similar
//! element counts (lavapipe runs a group's block under a mask for every invocation of the
//! dispatch, even where the group has no element). The trainer steps its eight groups in two
//! dispatches: means, scales, rotations, opacities and SH DC (1 to 4 floats per Gaussian), then
//! the three SH rest groups (15 each). Each group keeps its own buffers and learning rate; a
//! kernel for n groups binds 4n storage buffers, so kernels are built only for the counts the
//! adapter allows in one shader stage, and [`super::Adam::encode_steps`] falls back to one
//! dispatch per group elsewhere.

use std::fmt::Write as _;

use segsplat_gpu::kernel::{wgsl_u32_constants, workgroups_2d};
use segsplat_gpu::{GpuContext, GpuError, Kernel};

use super::{ADAM_UPDATE, ADAM_WORKGROUP, AdamConstants, AdamGroup, AdamSettings};

const ADAM_GROUPS_KERNEL: &str = include_str!("../adam_groups.wgsl");
/// Most groups one dispatch covers.
pub const ADAM_GROUPS: usize = 8;
/// Storage buffers per group: parameters, gradients, two moments.
const BUFFERS_PER_GROUP: usize = 4;

/// Uniform block of `adam_groups.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct AdamGroupsParams {
    constants: AdamConstants,
    step_size: [f32; ADAM_GROUPS],
    element_count: [u32; ADAM_GROUPS],
}

/// The fused kernels: `kernels[n - 2]` steps n groups.
#[derive(Debug)]
pub(super) struct AdamGroupsKernel {
    kernels: Vec<Kernel>,
}

/// The bindings of `groups` groups and `update_groups(index)`, a block per group (see
/// `adam_groups.wgsl`).
fn group_source(groups: usize) -> String {
    let mut source = String::new();
    let mut blocks = String::new();
    for g in 0..groups {
        let binding = 1 + BUFFERS_PER_GROUP * g;
        let _ = writeln!(
            source,
            "@group(0) @binding({}) var<storage, read_write> params_{g}: array<f32>;\n\
             @group(0) @binding({}) var<storage, read> grads_{g}: array<f32>;\n\
             @group(0) @binding({}) var<storage, read_write> first_moment_{g}: array<f32>;\n\
             @group(0) @binding({}) var<storage, read_write> second_moment_{g}: array<f32>;",
            binding,
            binding + 1,
            binding + 2,
            binding + 3,
        );
        let _ = writeln!(
            blocks,
            "    if index < group_element_count({g}u) {{\n\
             \x20       let gradient = grads_{g}[index];\n\
             \x20       if !adam_keeps(params.constants, gradient) {{\n\
             \x20           let e = adam_update(params.constants, group_step_size({g}u), params_{g}[index], gradient, first_moment_{g}[index], second_moment_{g}[index]);\n\
             \x20           first_moment_{g}[index] = e.first_moment;\n\
             \x20           second_moment_{g}[index] = e.second_moment;\n\
             \x20           params_{g}[index] = e.parameter;\n\
             \x20       }}\n\
             \x20   }}"
        );
    }
    let _ = write!(source, "fn update_groups(index: u32) {{\n{blocks}}}\n");
    source
}

impl AdamGroupsKernel {
    /// Kernels for 2 groups up to as many as the adapter binds (at most [`ADAM_GROUPS`]).
    pub(super) fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let bindable = ctx.limits.max_storage_buffers_per_shader_stage as usize / BUFFERS_PER_GROUP;
        let constants = wgsl_u32_constants(&[("ADAM_WORKGROUP", ADAM_WORKGROUP)]);
        let mut kernels = Vec::new();
        for groups in 2..=bindable.min(ADAM_GROUPS) {
            let source = group_source(groups);
            let kernel = Kernel::new(
                ctx,
                "adam_step_groups",
                &[&constants, ADAM_UPDATE, &source, ADAM_GROUPS_KERNEL],
                "adam_groups",
                &[],
            )?;
            kernels.push(kernel);
        }
        Ok(Self { kernels })
    }

    /// Whether one dispatch can step `groups` groups.
    pub(super) fn covers(&self, groups: usize) -> bool {
        groups >= 2 && groups - 2 < self.kernels.len()
    }

    /// Records one step of every group in `groups` (a count [`Self::covers`], buffers checked
    /// by the caller) with the bias corrections of step `step`.
    pub(super) fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        settings: &AdamSettings,
        groups: &[AdamGroup<'_>],
        step: u32,
    ) {
        let Some(kernel) = groups
            .len()
            .checked_sub(2)
            .and_then(|n| self.kernels.get(n))
        else {
            return;
        };
        let (constants, bias_correction1) = AdamConstants::at_step(settings, step);
        let mut params = AdamGroupsParams {
            constants,
            step_size: [0.0; ADAM_GROUPS],
            element_count: [0; ADAM_GROUPS],
        };
        for (g, group) in groups.iter().enumerate() {
            params.step_size[g] = (f64::from(group.learning_rate) / bias_correction1) as f32;
            params.element_count[g] = group.element_count;
        }
        let most = groups.iter().map(|group| group.element_count).max();
        let Some(most @ 1..) = most else {
            return;
        };
        let mut buffers: Vec<&wgpu::Buffer> = Vec::with_capacity(4 * groups.len());
        for group in groups {
            buffers.extend([
                group.buffers.params,
                group.buffers.grads,
                group.buffers.first_moment,
                group.buffers.second_moment,
            ]);
        }
        let bind_group = kernel.bind_params(ctx, bytemuck::bytes_of(&params), &buffers);
        let workgroups = most.div_ceil(ADAM_WORKGROUP);
        let grid = workgroups_2d(workgroups, ctx.limits.max_compute_workgroups_per_dimension);
        kernel.dispatch(encoder, &bind_group, grid);
    }
}
