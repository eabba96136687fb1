// Pass 4 of 4: vertical filtering of the SSIM partials, then the gradient of the weighted loss
// with respect to the rendered image:
//   dL/dr = weight / N * (0.8 * sign(r - t) - 0.2 * (G*d_mu + 2 r G*d_rr + t G*d_rt)).
// Overwrites `rendered_grad` (w = 0) where the gradient can be non-zero: everywhere for an
// unmasked loss; for object losses, which zero their gradient images first, the cells within
// reach of content. Each invocation filters a run of LOSS_RUN pixels of a column
// (loss_partials_run.wgsl).

@group(0) @binding(6) var<storage, read> row_partials: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> rendered_grad: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read> tile_distance: array<u32>;
@group(0) @binding(9) var<storage, read> work_items: array<vec2<u32>>;

fn partials_input(pixel: u32) -> Partials {
    let base = slot_pixel(pixel) * 3u;
    return Partials(row_partials[base], row_partials[base + 1u], row_partials[base + 2u]);
}

fn store_gradient(x: i32, y: i32, sum: Partials) {
    if y < i32(params.height) {
        let pixel = pixel_index(x, y);
        let r = rendered_rgb(pixel);
        let t = target_rgb(pixel);
        let dssim_dr = sum.d_mu.xyz + 2.0 * r * sum.d_rr.xyz + t * sum.d_rt.xyz;
        let grad = L1_WEIGHT * sign(r - t) - DSSIM_WEIGHT * dssim_dr;
        rendered_grad[(params.first_grad + slot) * pixel_count() + pixel] =
            vec4<f32>(params.weight * params.inv_value_count * grad, 0.0);
    }
}

@compute @workgroup_size(LOSS_TILE, LOSS_TILE / LOSS_RUN)
fn loss_gradient(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
) {
    let start = vertical_run(enter_tile(workgroup), local);
    let x = start.x;
    let y = start.y;
    // Beyond the reach of content the gradient is exactly zero (the images and all the moments
    // around are zero; sign(0) = 0), and already written.
    if !inside(x, y) || !cell_in_reach(x, y, REACH_GRADIENT) {
        return;
    }
    let run = filter_partials_run(x, y, vec2<i32>(0, 1), y, i32(params.height), REACH_ROW_PARTIALS);
    store_gradient(x, y, run.s0);
    store_gradient(x, y + 1, run.s1);
    store_gradient(x, y + 2, run.s2);
    store_gradient(x, y + 3, run.s3);
    store_gradient(x, y + 4, run.s4);
    store_gradient(x, y + 5, run.s5);
    store_gradient(x, y + 6, run.s6);
    store_gradient(x, y + 7, run.s7);
}
