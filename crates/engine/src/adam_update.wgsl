// One element's Adam update (PyTorch's formulation, as 3DGS uses it), shared by adam_step.wgsl
// (one group per dispatch) and adam_groups.wgsl (several groups per dispatch), so both run
// exactly the same arithmetic:
//   m = beta1 m + (1 - beta1) g;  v = beta2 v + (1 - beta2) g^2
//   p -= step_size * m / (sqrt(v) / sqrt(1 - beta2^t) + epsilon),  step_size = lr / (1 - beta1^t)
// Bias corrections are computed on the host in f64.

// What every group of a step shares; the first member of both kernels' uniform blocks.
struct AdamConstants {
    inv_sqrt_bias_correction2: f32,
    beta1: f32,
    beta2: f32,
    // 1 - beta, computed in f64 on the host: 1.0 - 0.999 in f32 is off by 1.3e-5 relative.
    one_minus_beta1: f32,
    one_minus_beta2: f32,
    epsilon: f32,
    // 1: elements whose gradient is exactly 0 keep their parameter and moments.
    skip_zero_gradients: u32,
    _pad: u32,
}

struct AdamElement {
    parameter: f32,
    first_moment: f32,
    second_moment: f32,
}

// Whether the element keeps its parameter and moments.
fn adam_keeps(c: AdamConstants, gradient: f32) -> bool {
    return c.skip_zero_gradients != 0u && gradient == 0.0;
}

fn adam_update(
    c: AdamConstants,
    step_size: f32,
    parameter: f32,
    gradient: f32,
    first_moment: f32,
    second_moment: f32,
) -> AdamElement {
    let m = c.beta1 * first_moment + c.one_minus_beta1 * gradient;
    let v = c.beta2 * second_moment + c.one_minus_beta2 * gradient * gradient;
    let denominator = sqrt(v) * c.inv_sqrt_bias_correction2 + c.epsilon;
    return AdamElement(parameter - step_size * m / denominator, m, v);
}
