// Per-fragment gradient emission without subgroups: each pixel adds its own fragment gradients
// into grad_projected (one atomic per non-zero slot). Slots: 0-1 mean2d, 2-4 conic, 5-7 colour,
// 8 opacity, 9-10 |d loss / d mean2d|.

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

// Called by every invocation of the workgroup for the same `gaussian`; `contributes` is false where
// the fragment does not contribute.
fn emit_fragment_grads(gaussian: u32, grads: FragmentGrads, contributes: bool) {
    if !contributes {
        return;
    }
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
