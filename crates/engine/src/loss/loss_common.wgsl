// Shared by the render-loss kernels (loss_*.wgsl): L = 0.8 * L1 + 0.2 * (1 - SSIM), SSIM as 3DGS
// (11x11 Gaussian window, sigma 1.5, zero padding, mean over pixels and RGB channels).
//
// Images are `array<vec4<f32>>`, width * height pixels, row-major, RGB in xyz (w ignored).
// The Gaussian window is prepended by the host as `SSIM_WINDOW` (11 normalised taps), together
// with `SSIM_C1`, `SSIM_C2`, `L1_WEIGHT` and `DSSIM_WEIGHT`.

const WINDOW_RADIUS: i32 = 5;
// Each workgroup covers a LOSS_TILE x LOSS_TILE square of pixels (LOSS_TILE and LOSS_RUN are
// prepended by the host, loss.rs, which sizes the dispatches and partial sums with them).
// Each invocation filters a run of LOSS_RUN consecutive pixels along its pass's direction, so
// each input pixel it reads serves up to LOSS_RUN outputs: LOSS_RUN + 10 reads instead of
// 11 LOSS_RUN. A CPU adapter reads memory lane by lane, so the reads dominate (lavapipe,
// 512x339: the four passes took ~52 ms a step one pixel per invocation).
// Runs of 8 rather than 4 cut reads per output from 3.5 to 2.25 for about 10% less loss time
// (a sliding window over the same runs, with no zero-weight multiply-adds, was 3x slower: it
// holds twice the values live, and they spill). The kernels hold LOSS_RUN named sums.
// Inputs a run reads: its pixels and the window's reach on both sides.
const RUN_INPUTS: i32 = i32(LOSS_RUN) + 2 * WINDOW_RADIUS;

struct LossParams {
    width: u32,
    height: u32,
    // 1 when the target is masked to pixels whose object id equals `object_id`.
    use_mask: u32,
    object_id: u32,
    // Scales the loss value and its gradient.
    weight: f32,
    // 1 / (width * height * 3).
    inv_value_count: f32,
    // Index written in the loss-values buffer.
    loss_slot: u32,
    // Workgroups of the per-pixel loss kernel (one partial sum each).
    partial_count: u32,
    // First pixel of the rendered image in `rendered`, and of the gradient in `rendered_grad`:
    // a batch of object renders is one buffer of images back to back.
    rendered_base: u32,
    grad_base: u32,
    padding0: u32,
    padding1: u32,
}

@group(0) @binding(0) var<uniform> params: LossParams;

var<private> window_weights: array<f32, 11> = SSIM_WINDOW;

// The window's weight at `tap` (0..11), zero outside it. A run's output k takes input j with tap
// j - k.
fn tap_weight(tap: i32) -> f32 {
    if tap < 0 || tap > 2 * WINDOW_RADIUS {
        return 0.0;
    }
    return window_weights[tap];
}

fn pixel_index(x: i32, y: i32) -> u32 {
    return u32(y) * params.width + u32(x);
}

fn inside(x: i32, y: i32) -> bool {
    return x >= 0 && y >= 0 && x < i32(params.width) && y < i32(params.height);
}

// The run (its first pixel) an invocation of a horizontal pass filters. Neighbouring lanes take
// neighbouring rows at the same x, as the vertical passes' lanes take neighbouring columns:
// then a run's loop bounds and edge tests are the same in every lane of a SIMD group, which a
// CPU adapter runs far faster than lanes spread along the row (lavapipe, figurine at 256 px:
// the two horizontal passes went from ~20 ms to ~6-8 ms a step each).
fn horizontal_run(workgroup: vec3<u32>, local: vec3<u32>) -> vec2<i32> {
    let origin = workgroup.xy * LOSS_TILE;
    return vec2<i32>(origin + vec2<u32>(local.y * LOSS_RUN, local.x));
}

const_assert LOSS_RUN == 8u;
