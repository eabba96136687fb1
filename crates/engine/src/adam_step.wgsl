// One Adam step over a flat f32 parameter array (PyTorch's formulation, as 3DGS uses it):
//   m = beta1 m + (1 - beta1) g;  v = beta2 v + (1 - beta2) g^2
//   p -= step_size * m / (sqrt(v) / sqrt(1 - beta2^t) + epsilon),  step_size = lr / (1 - beta1^t)
// Bias corrections are computed on the host in f64.

// ADAM_WORKGROUP and adam_update.wgsl are prepended by the host (adam.rs).

struct AdamParams {
    step_size: f32,
    inv_sqrt_bias_correction2: f32,
    beta1: f32,
    beta2: f32,
    // 1 - beta, computed in f64 on the host: 1.0 - 0.999 in f32 is off by 1.3e-5 relative.
    one_minus_beta1: f32,
    one_minus_beta2: f32,
    epsilon: f32,
    element_count: u32,
    // 1: elements whose gradient is exactly 0 keep their parameter and moments.
    skip_zero_gradients: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
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
    if params.skip_zero_gradients != 0u && gradient == 0.0 {
        return;
    }
    let updated = adam_update(
        params.step_size, params.inv_sqrt_bias_correction2, params.beta1, params.beta2,
        params.one_minus_beta1, params.one_minus_beta2, params.epsilon, parameters[index], gradient,
        first_moment[index], second_moment[index],
    );
    first_moment[index] = updated.first_moment;
    second_moment[index] = updated.second_moment;
    parameters[index] = updated.parameter;
}
