// Pass 2 of 4: vertical filtering completes the moments; then per pixel and channel the SSIM
// value and its partial derivatives with respect to the filtered moments
//   d_mu = dssim/d(G*r), d_rr = dssim/d(G*r^2), d_rt = dssim/d(G*r*t)
// (stored as three vec4, w = 0), and the pixel's unnormalised loss
//   0.8 * sum_c |r - t| + 0.2 * sum_c (1 - ssim_c),
// summed per workgroup in a fixed order (deterministic) into `loss_partials`.

@group(0) @binding(4) var<storage, read> row_moments: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> ssim_partials: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> loss_partials: array<f32>;

var<workgroup> tile_losses: array<f32, 256>;

@compute @workgroup_size(LOSS_TILE, LOSS_TILE)
fn ssim_per_pixel(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let x = i32(id.x);
    let y = i32(id.y);
    var pixel_loss = 0.0;
    if inside(x, y) {
        var mu_r = vec3<f32>(0.0);
        var mu_t = vec3<f32>(0.0);
        var m_rr = vec3<f32>(0.0);
        var m_tt = vec3<f32>(0.0);
        var m_rt = vec3<f32>(0.0);
        for (var tap = 0; tap < 11; tap++) {
            let sy = y + tap - WINDOW_RADIUS;
            if sy >= 0 && sy < i32(params.height) {
                let base = pixel_index(x, sy) * 4u;
                let weight = window_weights[tap];
                let a = row_moments[base];
                let b = row_moments[base + 1u];
                let c = row_moments[base + 2u];
                let d = row_moments[base + 3u];
                mu_r += weight * a.xyz;
                mu_t += weight * vec3<f32>(a.w, b.xy);
                m_rr += weight * vec3<f32>(b.zw, c.x);
                m_tt += weight * c.yzw;
                m_rt += weight * d.xyz;
            }
        }
        let var_r = m_rr - mu_r * mu_r;
        let var_t = m_tt - mu_t * mu_t;
        let cov = m_rt - mu_r * mu_t;
        let num_mean = 2.0 * mu_r * mu_t + SSIM_C1;
        let num_cov = 2.0 * cov + SSIM_C2;
        let den_mean = mu_r * mu_r + mu_t * mu_t + SSIM_C1;
        let den_var = var_r + var_t + SSIM_C2;
        let den = den_mean * den_var;
        let ssim = num_mean * num_cov / den;
        let d_mu = (2.0 * mu_t * num_cov - 2.0 * mu_t * num_mean) / den
            - 2.0 * mu_r * ssim / den_mean + 2.0 * mu_r * ssim / den_var;
        let d_rr = -ssim / den_var;
        let d_rt = 2.0 * num_mean / den;
        let base = pixel_index(x, y) * 3u;
        ssim_partials[base] = vec4<f32>(d_mu, 0.0);
        ssim_partials[base + 1u] = vec4<f32>(d_rr, 0.0);
        ssim_partials[base + 2u] = vec4<f32>(d_rt, 0.0);

        let pixel = pixel_index(x, y);
        let l1 = abs(rendered_rgb(pixel) - target_rgb(pixel));
        let dssim = vec3<f32>(1.0) - ssim;
        pixel_loss = L1_WEIGHT * (l1.x + l1.y + l1.z) + DSSIM_WEIGHT * (dssim.x + dssim.y + dssim.z);
    }
    tile_losses[thread] = pixel_loss;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride = stride >> 1u) {
        if thread < stride {
            tile_losses[thread] += tile_losses[thread + stride];
        }
        workgroupBarrier();
    }
    if thread == 0u {
        loss_partials[workgroup.x + workgroup.y * workgroups.x] = tile_losses[0];
    }
}
