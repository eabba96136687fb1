// Adam over up to ADAM_GROUPS parameter groups in one dispatch (adam_step.wgsl does one group per
// dispatch): invocation i steps element i of every group that has one. The host prepends
// ADAM_WORKGROUP, ADAM_GROUPS, adam_update.wgsl and, generated for each group g, its bindings
// (params_g, grads_g, first_moment_g, second_moment_g at bindings 1 + 4g ..= 4 + 4g) and
// `update_groups(index)`, one block per group (adam/groups.rs). One workgroup per group and a
// switch over the groups ran 4x slower on lavapipe than a dispatch per group.

struct AdamGroupsParams {
    inv_sqrt_bias_correction2: f32,
    beta1: f32,
    beta2: f32,
    // 1 - beta, computed in f64 on the host (adam_step.wgsl).
    one_minus_beta1: f32,
    one_minus_beta2: f32,
    epsilon: f32,
    // 1: elements whose gradient is exactly 0 keep their parameter and moments.
    skip_zero_gradients: u32,
    _pad: u32,
    // Per group, four to a vec4 (a uniform array's stride is 16 bytes).
    step_size: array<vec4<f32>, 2>,
    element_count: array<vec4<u32>, 2>,
}

@group(0) @binding(0) var<uniform> params: AdamGroupsParams;

fn group_step_size(g: u32) -> f32 {
    return params.step_size[g / 4u][g % 4u];
}

fn group_element_count(g: u32) -> u32 {
    return params.element_count[g / 4u][g % 4u];
}

// One element of a group after the step.
fn group_element(parameter: f32, gradient: f32, first_moment: f32, second_moment: f32, step_size: f32) -> AdamElement {
    return adam_update(
        step_size, params.inv_sqrt_bias_correction2, params.beta1, params.beta2,
        params.one_minus_beta1, params.one_minus_beta2, params.epsilon, parameter, gradient,
        first_moment, second_moment,
    );
}

// Whether the element keeps its parameter and moments (adam_step.wgsl's skip).
fn keeps_element(gradient: f32) -> bool {
    return params.skip_zero_gradients != 0u && gradient == 0.0;
}

@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_groups(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    update_groups((workgroup.x + workgroup.y * workgroups.x) * ADAM_WORKGROUP + thread);
}
