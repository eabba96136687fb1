// rasterize_forward.wgsl for software adapters: the same outputs, with each invocation
// compositing a column of 8 pixels of the 16x16 tile (a 16x2 workgroup). A CPU adapter runs a
// workgroup's invocations as SIMD lanes in a loop and reads workgroup memory lane by lane, so
// every splat's data read here serves 8 pixels (lavapipe, 512 px, 200k random Gaussians: forward
// pass 902 ms per pixel, 460 ms with columns of 4, 384 ms with columns of 8). Bindings and batch
// staging: rasterize_forward_common.wgsl.

const PIXELS: u32 = 8u;
const INVOCATIONS: u32 = 32u;

@compute @workgroup_size(16, 2)
fn rasterize_forward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tile = group.y * uniforms.tile_grid.x + group.x;
    let first_pixel = group.xy * TILE_SIZE + vec2<u32>(local.x, local.y * PIXELS);
    let range = load_tile_range(tile, local_index);
    let start = range.x;
    let end = range.y;
    let batches = (end - start + BATCH - 1u) / BATCH;

    var centre: array<vec2<f32>, 8>;
    var done: array<bool, 8>;
    var transmittance: array<f32, 8>;
    var rgb: array<vec3<f32>, 8>;
    var depth_sum: array<f32, 8>;
    var contributed: array<u32, 8>;
    var live = 0u;
    for (var p = 0u; p < PIXELS; p++) {
        let pixel = first_pixel + vec2<u32>(0u, p);
        centre[p] = vec2<f32>(pixel) + 0.5;
        done[p] = pixel.x >= uniforms.image_size.x || pixel.y >= uniforms.image_size.y;
        transmittance[p] = 1.0;
        rgb[p] = vec3<f32>(0.0);
        depth_sum[p] = 0.0;
        contributed[p] = 0u;
        live += u32(!done[p]);
    }
    for (var b = 0u; b < batches; b++) {
        if !any_invocation_active(live > 0u, local_index) {
            break;
        }
        for (var slot = local_index; start + b * BATCH + slot < end && slot < BATCH; slot += INVOCATIONS) {
            stage_splat(start + b * BATCH, slot);
        }
        workgroupBarrier();
        let batch_size = min(BATCH, end - start - b * BATCH);
        for (var t = 0u; t < batch_size; t++) {
            if live == 0u {
                break;
            }
            let splat = staged_splat(t);
            for (var p = 0u; p < PIXELS; p++) {
                let d = splat.mean_opacity.xy - centre[p];
                let sigma = splat_sigma(splat.conic, d);
                let alpha = min(ALPHA_MAX, splat.mean_opacity.z * exp(-sigma));
                if done[p] || sigma < 0.0 || alpha < ALPHA_MIN {
                    continue;
                }
                let next = transmittance[p] * (1.0 - alpha);
                if next <= TRANSMITTANCE_MIN {
                    done[p] = true;
                    live -= 1u;
                    continue;
                }
                let weight = alpha * transmittance[p];
                rgb[p] += splat.colour * weight;
                depth_sum[p] += splat.mean_opacity.w * weight;
                transmittance[p] = next;
                contributed[p] = b * BATCH + t + 1u;
            }
        }
        workgroupBarrier();
    }
    for (var p = 0u; p < PIXELS; p++) {
        let pixel = first_pixel + vec2<u32>(0u, p);
        if pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y {
            let index = pixel.y * uniforms.image_size.x + pixel.x;
            let t = transmittance[p];
            image[index] = vec4<f32>(rgb[p] + t * uniforms.background.xyz, 1.0 - t);
            final_transmittance[index] = t;
            last_contributor[index] = contributed[p];
            depth[index] = depth_sum[p];
        }
    }
}
