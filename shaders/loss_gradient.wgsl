// Pass 4 of 4: vertical filtering of the SSIM partials, then the gradient of the weighted loss
// with respect to the rendered image:
//   dL/dr = weight / N * (0.8 * sign(r - t) - 0.2 * (G*d_mu + 2 r G*d_rr + t G*d_rt)).
// Overwrites `rendered_grad` (w = 0).

@group(0) @binding(4) var<storage, read> row_partials: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> rendered_grad: array<vec4<f32>>;

@compute @workgroup_size(LOSS_TILE, LOSS_TILE)
fn loss_gradient(@builtin(global_invocation_id) id: vec3<u32>) {
    let x = i32(id.x);
    let y = i32(id.y);
    if !inside(x, y) {
        return;
    }
    var d_mu = vec3<f32>(0.0);
    var d_rr = vec3<f32>(0.0);
    var d_rt = vec3<f32>(0.0);
    for (var tap = 0; tap < 11; tap++) {
        let sy = y + tap - WINDOW_RADIUS;
        if sy >= 0 && sy < i32(params.height) {
            let base = pixel_index(x, sy) * 3u;
            let weight = window_weights[tap];
            d_mu += weight * row_partials[base].xyz;
            d_rr += weight * row_partials[base + 1u].xyz;
            d_rt += weight * row_partials[base + 2u].xyz;
        }
    }
    let pixel = pixel_index(x, y);
    let r = rendered_rgb(pixel);
    let t = target_rgb(pixel);
    let dssim_dr = d_mu + 2.0 * r * d_rr + t * d_rt;
    let grad = L1_WEIGHT * sign(r - t) - DSSIM_WEIGHT * dssim_dr;
    rendered_grad[pixel] = vec4<f32>(params.weight * params.inv_value_count * grad, 0.0);
}
