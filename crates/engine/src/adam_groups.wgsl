// Adam over n parameter groups in one dispatch (2 <= n <= 8; adam_step.wgsl does one group per
// dispatch): invocation i steps element i of every group that has one. The host prepends
// ADAM_WORKGROUP, adam_update.wgsl and, generated for each group g < n, its bindings
// (params_g, grads_g, first_moment_g, second_moment_g at bindings 1 + 4g ..= 4 + 4g) and
// `update_groups(index)`, one block per group (adam/groups.rs). One workgroup per group and a
// switch over the groups ran 4x slower on lavapipe than a dispatch per group.

struct AdamGroupsParams {
    constants: AdamConstants,
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

@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_groups(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    update_groups((workgroup.x + workgroup.y * workgroups.x) * ADAM_WORKGROUP + thread);
}
