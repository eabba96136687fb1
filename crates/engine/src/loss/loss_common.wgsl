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

// One dispatch computes one unmasked loss (the full render's: every workgroup the tile at its id)
// or a batch of object losses (`use_mask`: each slot's target masked to its object, each
// workgroup one (slot, tile) of a work list). Slot s of a dispatch compares rendered image
// `first_rendered + s` with its masked target, keeps its intermediates in image s of the scratch
// buffers, and writes gradient image `first_grad + s` and loss value `first_loss_slot + s`.
struct LossParams {
    width: u32,
    height: u32,
    use_mask: u32,
    slot_count: u32,
    // Scales the loss values and their gradients.
    weight: f32,
    // 1 / (width * height * 3).
    inv_value_count: f32,
    first_loss_slot: u32,
    first_rendered: u32,
    first_grad: u32,
    // Loss partial sums per slot: per-pixel workgroups (tiles) times their invocations.
    partial_count: u32,
    tiles_x: u32,
    padding0: u32,
    // Per slot: x = which object-id map its mask reads (loss_inputs.wgsl), y = its object id.
    slots: array<vec4<u32>, MAX_BATCH_SLOTS>,
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

// The slot this invocation computes (0 for an unmasked loss); the kernels set it first.
var<private> slot: u32;

fn pixel_index(x: i32, y: i32) -> u32 {
    return u32(y) * params.width + u32(x);
}

fn pixel_count() -> u32 {
    return params.width * params.height;
}

// Where `pixel` of this invocation's slot lies in a scratch buffer holding one image per slot.
fn slot_pixel(pixel: u32) -> u32 {
    return slot * pixel_count() + pixel;
}

// The skip cells (SKIP_CELL x SKIP_CELL) across and down the image.
fn cell_grid() -> vec2<u32> {
    return (vec2<u32>(params.width, params.height) + SKIP_CELL - 1u) / SKIP_CELL;
}

fn inside(x: i32, y: i32) -> bool {
    return x >= 0 && y >= 0 && x < i32(params.width) && y < i32(params.height);
}

// The run (its first pixel) an invocation of a horizontal pass filters in `tile`. Neighbouring
// lanes take neighbouring rows at the same x, as the vertical passes' lanes take neighbouring
// columns: then a run's loop bounds and edge tests are the same in every lane of a SIMD group,
// which a CPU adapter runs far faster than lanes spread along the row (lavapipe, figurine at
// 256 px: the two horizontal passes went from ~20 ms to ~6-8 ms a step each).
fn horizontal_run(tile: vec2<u32>, local: vec3<u32>) -> vec2<i32> {
    let origin = tile * LOSS_TILE;
    return vec2<i32>(origin + vec2<u32>(local.y * LOSS_RUN, local.x));
}

// The run (its first pixel) an invocation of a vertical pass filters in `tile`.
fn vertical_run(tile: vec2<u32>, local: vec3<u32>) -> vec2<i32> {
    let origin = tile * LOSS_TILE;
    return vec2<i32>(origin + vec2<u32>(local.x, local.y * LOSS_RUN));
}

const_assert LOSS_RUN == 8u;
