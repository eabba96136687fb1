// One fragment's gradients and the atomic add both emission variants share
// (rasterize_grad_emit_direct.wgsl, rasterize_grad_emit_subgroup.wgsl). Slots in grad_projected:
// 0-1 mean2d, 2-4 conic, 5-7 colour, 8 opacity, 9-10 |d loss / d mean2d|.

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

fn add_fragment_grads(gaussian: u32, grads: FragmentGrads) {
    add_grad(gaussian, 0u, grads.mean.x);
    add_grad(gaussian, 1u, grads.mean.y);
    add_grad(gaussian, 2u, grads.conic.x);
    add_grad(gaussian, 3u, grads.conic.y);
    add_grad(gaussian, 4u, grads.conic.z);
    add_grad(gaussian, 5u, grads.colour.x);
    add_grad(gaussian, 6u, grads.colour.y);
    add_grad(gaussian, 7u, grads.colour.z);
    add_grad(gaussian, 8u, grads.opacity);
    add_grad(gaussian, 9u, grads.mean_abs.x);
    add_grad(gaussian, 10u, grads.mean_abs.y);
}
