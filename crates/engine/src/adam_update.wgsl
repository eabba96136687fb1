// One element's Adam update, shared by adam_step.wgsl (one group per dispatch) and
// adam_groups.wgsl (every group in one dispatch), so both run exactly the same arithmetic.

struct AdamElement {
    parameter: f32,
    first_moment: f32,
    second_moment: f32,
}

fn adam_update(
    step_size: f32,
    inv_sqrt_bias_correction2: f32,
    beta1: f32,
    beta2: f32,
    one_minus_beta1: f32,
    one_minus_beta2: f32,
    epsilon: f32,
    parameter: f32,
    gradient: f32,
    first_moment: f32,
    second_moment: f32,
) -> AdamElement {
    let m = beta1 * first_moment + one_minus_beta1 * gradient;
    let v = beta2 * second_moment + one_minus_beta2 * gradient * gradient;
    let denominator = sqrt(v) * inv_sqrt_bias_correction2 + epsilon;
    return AdamElement(parameter - step_size * m / denominator, m, v);
}
