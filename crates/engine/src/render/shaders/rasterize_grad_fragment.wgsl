// One fragment's gradients and the atomic add both emission variants share
// (rasterize_grad_emit_*.wgsl). Slots in grad_projected:
// 0-1 mean2d, 2-4 conic, 5-7 colour, 8 opacity, 9-10 |d loss / d mean2d|.

const GRAD_SLOTS: u32 = 11u;

// Slots this render adds: object renders leave out |d loss / d mean2d| (uniforms.mean2d_abs), two
// atomics fewer per emission.
fn emitted_grad_slots() -> u32 {
    return select(GRAD_SLOTS - 2u, GRAD_SLOTS, uniforms.mean2d_abs != 0u);
}

struct FragmentGrads {
    mean: vec2<f32>,
    conic: vec3<f32>,
    colour: vec3<f32>,
    opacity: f32,
    mean_abs: vec2<f32>,
}

fn no_fragment_grads() -> FragmentGrads {
    return FragmentGrads(vec2<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, vec2<f32>(0.0));
}

fn sum_fragment_grads(a: FragmentGrads, b: FragmentGrads) -> FragmentGrads {
    return FragmentGrads(a.mean + b.mean, a.conic + b.conic, a.colour + b.colour, a.opacity + b.opacity, a.mean_abs + b.mean_abs);
}

// No test for zero: the branch costs a CPU adapter more than the atomic it would save (lavapipe,
// 512 px, 200k random Gaussians: column backward 613 ms without it, 650-670 ms with it).
fn add_grad(gaussian: u32, slot: u32, value: f32) {
    grad_projected_add(gaussian * GRAD_STRIDE + slot, value);
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
    if uniforms.mean2d_abs != 0u {
        add_grad(gaussian, 9u, grads.mean_abs.x);
        add_grad(gaussian, 10u, grads.mean_abs.y);
    }
}

// A contributing fragment's gradients at one pixel. `transmittance` is the transmittance in
// front of the fragment (already divided back by 1 - alpha), `behind` the colour composited
// behind it, `value` the Gaussian falloff exp(-sigma) at offset `d`, `v_rgb` d loss / d rgb of
// the pixel and `final_term` its `final_alpha_term` (what the pixel's final transmittance and
// d loss / d alpha contribute).

// T_final (d loss / d alpha - dot(background, d loss / d rgb)): alpha = 1 - T_final and the
// background shows through T_final, so this is the same for every fragment of the pixel.
fn final_alpha_term(t_final: f32, v_out: vec4<f32>, background: vec3<f32>) -> f32 {
    return t_final * (v_out.w - dot(background, v_out.xyz));
}

fn fragment_grads(
    mean_opacity: vec4<f32>,
    conic: vec3<f32>,
    colour: vec3<f32>,
    d: vec2<f32>,
    value: f32,
    alpha: f32,
    transmittance: f32,
    one_over_rest: f32,
    behind: vec3<f32>,
    v_rgb: vec3<f32>,
    final_term: f32,
) -> FragmentGrads {
    var grads = no_fragment_grads();
    let weight = alpha * transmittance;
    var v_alpha = dot(colour * transmittance - behind * one_over_rest, v_rgb);
    v_alpha += final_term * one_over_rest;
    grads.colour = weight * v_rgb;
    // Where the opacity clamp at ALPHA_MAX binds, alpha does not depend on the geometry.
    if mean_opacity.z * value <= ALPHA_MAX {
        let v_sigma = -mean_opacity.z * value * v_alpha;
        let v_mean = v_sigma * vec2<f32>(conic.x * d.x + conic.y * d.y, conic.y * d.x + conic.z * d.y);
        grads.mean = v_mean;
        grads.conic = vec3<f32>(0.5 * v_sigma * d.x * d.x, v_sigma * d.x * d.y, 0.5 * v_sigma * d.y * d.y);
        grads.opacity = value * v_alpha;
        grads.mean_abs = abs(v_mean);
    }
    return grads;
}
