// Pass 1 of 4: horizontal Gaussian filtering of the five SSIM moment images
// (r, t, r*r, t*t, r*t per channel), packed in four vec4 per pixel:
// (r.xyz, t.x) (t.yz, rr.xy) (rr.z, tt.xyz) (rt.xyz, 0). Each invocation filters a run of
// LOSS_RUN pixels of a row.

@group(0) @binding(6) var<storage, read_write> row_moments: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> tile_distance: array<u32>;
@group(0) @binding(8) var<storage, read> work_items: array<vec2<u32>>;

struct Moments {
    r: vec3<f32>,
    t: vec3<f32>,
    rr: vec3<f32>,
    tt: vec3<f32>,
    rt: vec3<f32>,
}

fn no_moments() -> Moments {
    return Moments(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
}

fn add_moments(m: Moments, weight: f32, r: vec3<f32>, t: vec3<f32>) -> Moments {
    return Moments(
        m.r + weight * r,
        m.t + weight * t,
        m.rr + weight * r * r,
        m.tt + weight * t * t,
        m.rt + weight * r * t,
    );
}

fn store_moments(x: i32, y: i32, m: Moments) {
    if x < i32(params.width) {
        let base = slot_pixel(pixel_index(x, y)) * 4u;
        row_moments[base] = vec4<f32>(m.r, m.t.x);
        row_moments[base + 1u] = vec4<f32>(m.t.yz, m.rr.xy);
        row_moments[base + 2u] = vec4<f32>(m.rr.z, m.tt);
        row_moments[base + 3u] = vec4<f32>(m.rt, 0.0);
    }
}

@compute @workgroup_size(LOSS_TILE, LOSS_TILE / LOSS_RUN)
fn filter_moments_horizontal(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
) {
    let start = horizontal_run(enter_tile(workgroup), local);
    let x = start.x;
    let y = start.y;
    if !inside(x, y) || !cell_in_reach(x, y, REACH_ROW_MOMENTS) {
        return;
    }
    var m0 = no_moments();
    var m1 = no_moments();
    var m2 = no_moments();
    var m3 = no_moments();
    var m4 = no_moments();
    var m5 = no_moments();
    var m6 = no_moments();
    var m7 = no_moments();
    for (var j = 0; j < RUN_INPUTS; j++) {
        let sx = x + j - WINDOW_RADIUS;
        if sx >= 0 && sx < i32(params.width) {
            let pixel = pixel_index(sx, y);
            let r = rendered_rgb(pixel);
            let t = target_rgb(pixel);
            m0 = add_moments(m0, tap_weight(j), r, t);
            m1 = add_moments(m1, tap_weight(j - 1), r, t);
            m2 = add_moments(m2, tap_weight(j - 2), r, t);
            m3 = add_moments(m3, tap_weight(j - 3), r, t);
            m4 = add_moments(m4, tap_weight(j - 4), r, t);
            m5 = add_moments(m5, tap_weight(j - 5), r, t);
            m6 = add_moments(m6, tap_weight(j - 6), r, t);
            m7 = add_moments(m7, tap_weight(j - 7), r, t);
        }
    }
    store_moments(x, y, m0);
    store_moments(x + 1, y, m1);
    store_moments(x + 2, y, m2);
    store_moments(x + 3, y, m3);
    store_moments(x + 4, y, m4);
    store_moments(x + 5, y, m5);
    store_moments(x + 6, y, m6);
    store_moments(x + 7, y, m7);
}
