// One Adam step over a flat f32 parameter array (the update: adam_update.wgsl).

// ADAM_WORKGROUP and adam_update.wgsl are prepended by the host (adam.rs).

struct AdamParams {
    constants: AdamConstants,
    step_size: f32,
    element_count: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: AdamParams;
@group(0) @binding(1) var<storage, read_write> parameters: array<f32>;
@group(0) @binding(2) var<storage, read> gradients: array<f32>;
@group(0) @binding(3) var<storage, read_write> first_moment: array<f32>;
@group(0) @binding(4) var<storage, read_write> second_moment: array<f32>;

@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_step(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let index = (workgroup.x + workgroup.y * workgroups.x) * ADAM_WORKGROUP + thread;
    if index >= params.element_count {
        return;
    }
    let gradient = gradients[index];
    if adam_keeps(params.constants, gradient) {
        return;
    }
    let updated = adam_update(
        params.constants, params.step_size, parameters[index], gradient, first_moment[index],
        second_moment[index],
    );
    first_moment[index] = updated.first_moment;
    second_moment[index] = updated.second_moment;
    parameters[index] = updated.parameter;
}
