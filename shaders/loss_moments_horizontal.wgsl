// Pass 1 of 4: horizontal Gaussian filtering of the five SSIM moment images
// (r, t, r*r, t*t, r*t per channel), packed in four vec4 per pixel:
// (r.xyz, t.x) (t.yz, rr.xy) (rr.z, tt.xyz) (rt.xyz, 0).

@group(0) @binding(4) var<storage, read_write> row_moments: array<vec4<f32>>;

@compute @workgroup_size(LOSS_TILE, LOSS_TILE)
fn filter_moments_horizontal(@builtin(global_invocation_id) id: vec3<u32>) {
    let x = i32(id.x);
    let y = i32(id.y);
    if !inside(x, y) {
        return;
    }
    var r = vec3<f32>(0.0);
    var t = vec3<f32>(0.0);
    var rr = vec3<f32>(0.0);
    var tt = vec3<f32>(0.0);
    var rt = vec3<f32>(0.0);
    for (var tap = 0; tap < 11; tap++) {
        let sx = x + tap - WINDOW_RADIUS;
        if sx >= 0 && sx < i32(params.width) {
            let pixel = pixel_index(sx, y);
            let weight = window_weights[tap];
            let rendered_value = rendered_rgb(pixel);
            let target_value = target_rgb(pixel);
            r += weight * rendered_value;
            t += weight * target_value;
            rr += weight * rendered_value * rendered_value;
            tt += weight * target_value * target_value;
            rt += weight * rendered_value * target_value;
        }
    }
    let base = pixel_index(x, y) * 4u;
    row_moments[base] = vec4<f32>(r, t.x);
    row_moments[base + 1u] = vec4<f32>(t.yz, rr.xy);
    row_moments[base + 2u] = vec4<f32>(rr.z, tt);
    row_moments[base + 3u] = vec4<f32>(rt, 0.0);
}
