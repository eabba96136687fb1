// Pass 3 of 4: horizontal Gaussian filtering of the SSIM partials (the adjoint of the forward
// filter: the window is symmetric and zero padding drops the same out-of-image terms). Each
// invocation filters a run of LOSS_RUN pixels of a row.

@group(0) @binding(1) var<storage, read> ssim_partials: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> row_partials: array<vec4<f32>>;

fn store_partials(x: i32, y: i32, sum: Partials) {
    if x < i32(params.width) {
        let base = pixel_index(x, y) * 3u;
        row_partials[base] = sum.d_mu;
        row_partials[base + 1u] = sum.d_rr;
        row_partials[base + 2u] = sum.d_rt;
    }
}

@compute @workgroup_size(LOSS_TILE / LOSS_RUN, LOSS_TILE)
fn filter_partials_horizontal(@builtin(global_invocation_id) id: vec3<u32>) {
    let x = i32(id.x * LOSS_RUN);
    let y = i32(id.y);
    if !inside(x, y) {
        return;
    }
    var s0 = no_partials();
    var s1 = no_partials();
    var s2 = no_partials();
    var s3 = no_partials();
    for (var j = 0; j < RUN_INPUTS; j++) {
        let sx = x + j - WINDOW_RADIUS;
        if sx >= 0 && sx < i32(params.width) {
            let base = pixel_index(sx, y) * 3u;
            let value = Partials(ssim_partials[base], ssim_partials[base + 1u], ssim_partials[base + 2u]);
            s0 = add_partials(s0, tap_weight(j), value);
            s1 = add_partials(s1, tap_weight(j - 1), value);
            s2 = add_partials(s2, tap_weight(j - 2), value);
            s3 = add_partials(s3, tap_weight(j - 3), value);
        }
    }
    store_partials(x, y, s0);
    store_partials(x + 1, y, s1);
    store_partials(x + 2, y, s2);
    store_partials(x + 3, y, s3);
}
