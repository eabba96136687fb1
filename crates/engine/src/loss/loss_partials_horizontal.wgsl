// Pass 3 of 4: horizontal Gaussian filtering of the SSIM partials (the adjoint of the forward
// filter: the window is symmetric and zero padding drops the same out-of-image terms). Each
// invocation filters a run of LOSS_RUN pixels of a row (loss_partials_run.wgsl).

@group(0) @binding(1) var<storage, read> ssim_partials: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> row_partials: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> tile_distance: array<u32>;
@group(0) @binding(4) var<storage, read> work_items: array<vec2<u32>>;

fn partials_input(pixel: u32) -> Partials {
    let base = slot_pixel(pixel) * 3u;
    return Partials(ssim_partials[base], ssim_partials[base + 1u], ssim_partials[base + 2u]);
}

fn store_partials(x: i32, y: i32, sum: Partials) {
    if x < i32(params.width) {
        let base = slot_pixel(pixel_index(x, y)) * 3u;
        row_partials[base] = sum.d_mu;
        row_partials[base + 1u] = sum.d_rr;
        row_partials[base + 2u] = sum.d_rt;
    }
}

@compute @workgroup_size(LOSS_TILE, LOSS_TILE / LOSS_RUN)
fn filter_partials_horizontal(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
) {
    let start = horizontal_run(enter_tile(workgroup), local);
    let x = start.x;
    let y = start.y;
    if !inside(x, y) || !cell_in_reach(x, y, REACH_ROW_PARTIALS) {
        return;
    }
    let run = filter_partials_run(x, y, vec2<i32>(1, 0), x, i32(params.width), REACH_SSIM);
    store_partials(x, y, run.s0);
    store_partials(x + 1, y, run.s1);
    store_partials(x + 2, y, run.s2);
    store_partials(x + 3, y, run.s3);
    store_partials(x + 4, y, run.s4);
    store_partials(x + 5, y, run.s5);
    store_partials(x + 6, y, run.s6);
    store_partials(x + 7, y, run.s7);
}
