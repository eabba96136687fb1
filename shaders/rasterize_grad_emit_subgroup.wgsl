// Per-fragment gradient emission with subgroups: every invocation of a subgroup works on the same
// Gaussian at the same time (the batch loop is uniform), so the subgroup sums its fragments'
// gradients first and one invocation adds the sums: subgroup-size times fewer atomics on the
// hottest addresses (8 on lavapipe's 256-bit lanes, 32 on NVIDIA). naga takes the subgroup
// builtins from the device's SUBGROUP feature (it rejects `enable subgroups;`).

struct FragmentGrads {
    mean: vec2<f32>,
    conic: vec3<f32>,
    colour: vec3<f32>,
    opacity: f32,
    mean_abs: vec2<f32>,
}

fn add_grad(gaussian: u32, slot: u32, value: f32) {
    if value != 0.0 {
        grad_projected_add(gaussian * GRAD_STRIDE + slot, value);
    }
}

// Must be called in uniform control flow by every invocation; inactive ones contribute zeros.
fn emit_fragment_grads(gaussian: u32, grads: FragmentGrads, contributes: bool) {
    let zero = FragmentGrads(vec2<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, vec2<f32>(0.0));
    var mine = zero;
    if contributes {
        mine = grads;
    }
    if !subgroupAny(contributes) {
        return;
    }
    let mean = subgroupAdd(mine.mean);
    let conic = subgroupAdd(mine.conic);
    let colour = subgroupAdd(mine.colour);
    let opacity = subgroupAdd(mine.opacity);
    let mean_abs = subgroupAdd(mine.mean_abs);
    // naga has no subgroupElect: the invocation with no active one before it adds.
    if subgroupExclusiveAdd(1u) == 0u {
        add_grad(gaussian, 0u, mean.x);
        add_grad(gaussian, 1u, mean.y);
        add_grad(gaussian, 2u, conic.x);
        add_grad(gaussian, 3u, conic.y);
        add_grad(gaussian, 4u, conic.z);
        add_grad(gaussian, 5u, colour.x);
        add_grad(gaussian, 6u, colour.y);
        add_grad(gaussian, 7u, colour.z);
        add_grad(gaussian, 8u, opacity);
        add_grad(gaussian, 9u, mean_abs.x);
        add_grad(gaussian, 10u, mean_abs.y);
    }
}
