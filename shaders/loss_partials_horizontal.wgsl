// Pass 3 of 4: horizontal Gaussian filtering of the SSIM partials (the adjoint of the forward
// filter: the window is symmetric and zero padding drops the same out-of-image terms).

@group(0) @binding(1) var<storage, read> ssim_partials: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> row_partials: array<vec4<f32>>;

@compute @workgroup_size(LOSS_TILE, LOSS_TILE)
fn filter_partials_horizontal(@builtin(global_invocation_id) id: vec3<u32>) {
    let x = i32(id.x);
    let y = i32(id.y);
    if !inside(x, y) {
        return;
    }
    var d_mu = vec4<f32>(0.0);
    var d_rr = vec4<f32>(0.0);
    var d_rt = vec4<f32>(0.0);
    for (var tap = 0; tap < 11; tap++) {
        let sx = x + tap - WINDOW_RADIUS;
        if sx >= 0 && sx < i32(params.width) {
            let base = pixel_index(sx, y) * 3u;
            let weight = window_weights[tap];
            d_mu += weight * ssim_partials[base];
            d_rr += weight * ssim_partials[base + 1u];
            d_rt += weight * ssim_partials[base + 2u];
        }
    }
    let base = pixel_index(x, y) * 3u;
    row_partials[base] = d_mu;
    row_partials[base + 1u] = d_rr;
    row_partials[base + 2u] = d_rt;
}
