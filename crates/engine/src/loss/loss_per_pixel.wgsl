// Pass 2 of 4: vertical filtering completes the moments; then per pixel and channel the SSIM
// value and its partial derivatives with respect to the filtered moments
//   d_mu = dssim/d(G*r), d_rr = dssim/d(G*r^2), d_rt = dssim/d(G*r*t)
// (stored as three vec4, w = 0), and the pixel's unnormalised loss
//   0.8 * sum_c |r - t| + 0.2 * sum_c (1 - ssim_c),
// one partial sum per invocation in `loss_partials` (loss_reduce.wgsl sums them in a fixed
// order). Each invocation filters a run of LOSS_RUN pixels of a column. No workgroup memory or
// barriers: a CPU adapter pays a barrier in every workgroup, and an object loss skips most.

@group(0) @binding(6) var<storage, read> row_moments: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> ssim_partials: array<vec4<f32>>;
// Per slot `partial_count` sums, zeroed before an object loss (its unlisted tiles add nothing).
@group(0) @binding(8) var<storage, read_write> loss_partials: array<f32>;
@group(0) @binding(9) var<storage, read> tile_distance: array<u32>;
@group(0) @binding(10) var<storage, read> work_items: array<vec2<u32>>;

const INVOCATIONS: u32 = LOSS_TILE * LOSS_TILE / LOSS_RUN;

// The moments as pass 1 packs them: (r.xyz, t.x) (t.yz, rr.xy) (rr.z, tt.xyz) (rt.xyz, 0).
struct PackedMoments {
    a: vec4<f32>,
    b: vec4<f32>,
    c: vec4<f32>,
    d: vec4<f32>,
}

fn no_packed_moments() -> PackedMoments {
    return PackedMoments(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
}

fn add_packed_moments(sum: PackedMoments, weight: f32, value: PackedMoments) -> PackedMoments {
    return PackedMoments(
        sum.a + weight * value.a,
        sum.b + weight * value.b,
        sum.c + weight * value.c,
        sum.d + weight * value.d,
    );
}

// Writes the SSIM partials of pixel (x, y) from its filtered moments and returns its loss
// (0 outside the image).
fn ssim_pixel(x: i32, y: i32, m: PackedMoments) -> f32 {
    if !inside(x, y) {
        return 0.0;
    }
    let mu_r = m.a.xyz;
    let mu_t = vec3<f32>(m.a.w, m.b.xy);
    let m_rr = vec3<f32>(m.b.zw, m.c.x);
    let m_tt = m.c.yzw;
    let m_rt = m.d.xyz;
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
    let pixel = pixel_index(x, y);
    let base = slot_pixel(pixel) * 3u;
    ssim_partials[base] = vec4<f32>(d_mu, 0.0);
    ssim_partials[base + 1u] = vec4<f32>(d_rr, 0.0);
    ssim_partials[base + 2u] = vec4<f32>(d_rt, 0.0);
    let l1 = abs(rendered_rgb(pixel) - target_rgb(pixel));
    let dssim = vec3<f32>(1.0) - ssim;
    return L1_WEIGHT * (l1.x + l1.y + l1.z) + DSSIM_WEIGHT * (dssim.x + dssim.y + dssim.z);
}

@compute @workgroup_size(LOSS_TILE, LOSS_TILE / LOSS_RUN)
fn ssim_per_pixel(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let tile = enter_tile(workgroup);
    let start = vertical_run(tile, local);
    let x = start.x;
    let y = start.y;
    var run_loss = 0.0;
    // A skipped cell's loss is exactly zero.
    if inside(x, y) && cell_in_reach(x, y, REACH_SSIM) {
        // Row moments the first pass skipped are zero (loss_skip.wgsl).
        let reach = run_reach(x, y, vec2<i32>(0, 1), y, i32(params.height), REACH_ROW_MOMENTS);
        var m0 = no_packed_moments();
        var m1 = no_packed_moments();
        var m2 = no_packed_moments();
        var m3 = no_packed_moments();
        var m4 = no_packed_moments();
        var m5 = no_packed_moments();
        var m6 = no_packed_moments();
        var m7 = no_packed_moments();
        for (var j = 0; j < RUN_INPUTS; j++) {
            let sy = y + j - WINDOW_RADIUS;
            if sy >= 0 && sy < i32(params.height) && input_computed(reach, sy) {
                let base = slot_pixel(pixel_index(x, sy)) * 4u;
                let row = PackedMoments(
                    row_moments[base],
                    row_moments[base + 1u],
                    row_moments[base + 2u],
                    row_moments[base + 3u],
                );
                m0 = add_packed_moments(m0, tap_weight(j), row);
                m1 = add_packed_moments(m1, tap_weight(j - 1), row);
                m2 = add_packed_moments(m2, tap_weight(j - 2), row);
                m3 = add_packed_moments(m3, tap_weight(j - 3), row);
                m4 = add_packed_moments(m4, tap_weight(j - 4), row);
                m5 = add_packed_moments(m5, tap_weight(j - 5), row);
                m6 = add_packed_moments(m6, tap_weight(j - 6), row);
                m7 = add_packed_moments(m7, tap_weight(j - 7), row);
            }
        }
        run_loss = ssim_pixel(x, y, m0) + ssim_pixel(x, y + 1, m1) + ssim_pixel(x, y + 2, m2)
            + ssim_pixel(x, y + 3, m3);
        run_loss += ssim_pixel(x, y + 4, m4) + ssim_pixel(x, y + 5, m5)
            + ssim_pixel(x, y + 6, m6) + ssim_pixel(x, y + 7, m7);
    }
    let tile_index = tile.y * params.tiles_x + tile.x;
    loss_partials[slot * params.partial_count + tile_index * INVOCATIONS + thread] = run_loss;
}
