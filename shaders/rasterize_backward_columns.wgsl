// rasterize_backward.wgsl for software adapters: the same gradients, with each invocation
// walking a column of 4 pixels of the 16x16 tile (a 16x4 workgroup). A CPU adapter runs a
// workgroup's invocations as SIMD lanes in a loop and reads workgroup memory lane by lane, and its
// float atomics are compare-and-swap loops: here every splat's data is read once for 4 pixels,
// and the 4 pixels' gradients are summed in registers before they are emitted (lavapipe, 512
// px, 200k random Gaussians: backward pass 2194 ms per pixel, 963 ms with columns of 4; columns
// of 8 gained nothing more). With subgroups, the subgroup's sums are added up by shuffles before
// the atomics (rasterize_grad_emit_shuffle.wgsl). Bindings, batch staging and the fragment's
// gradients: rasterize_backward_common.wgsl and rasterize_grad_fragment.wgsl.

const PIXELS: u32 = 4u;
const INVOCATIONS: u32 = 64u;

@compute @workgroup_size(16, 4)
fn rasterize_backward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tile = group.y * uniforms.tile_grid.x + group.x;
    let first_pixel = group.xy * TILE_SIZE + vec2<u32>(local.x, local.y * PIXELS);

    // Per pixel, only what the walk needs (a CPU adapter spills what does not fit its vector
    // registers): the column's pixels share x, so their centres differ in y only.
    let centre_x = f32(first_pixel.x) + 0.5;
    var centre_y: array<f32, 4>;
    var contributed: array<u32, 4>;
    var v_rgb: array<vec3<f32>, 4>;
    var final_term: array<f32, 4>;
    var transmittance: array<f32, 4>;
    var behind: array<vec3<f32>, 4>;
    emit_setup();
    var most = 0u;
    for (var p = 0u; p < PIXELS; p++) {
        let pixel = first_pixel + vec2<u32>(0u, p);
        centre_y[p] = f32(pixel.y) + 0.5;
        var t_final = 1.0;
        contributed[p] = 0u;
        var v_out = vec4<f32>(0.0);
        if pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y {
            let index = pixel.y * uniforms.image_size.x + pixel.x;
            t_final = final_transmittance[index];
            contributed[p] = last_contributor[index];
            v_out = grad_image[index];
        }
        v_rgb[p] = v_out.xyz;
        final_term[p] = final_alpha_term(t_final, v_out, uniforms.background.xyz);
        transmittance[p] = t_final;
        behind[p] = vec3<f32>(0.0);
        most = max(most, contributed[p]);
    }
    let walk = tile_walk(tile, local_index, most);
    let start = walk.x;
    let count = walk.y;
    let batches = (count + BATCH - 1u) / BATCH;

    for (var b = 0u; b < batches; b++) {
        // Batch b holds range positions [count - (b + 1) * BATCH, count - b * BATCH), back to front.
        let batch_end = count - b * BATCH;
        let batch_size = min(BATCH, batch_end);
        for (var slot = local_index; slot < batch_size; slot += INVOCATIONS) {
            stage_splat_backwards(start, batch_end, slot);
        }
        workgroupBarrier();
        for (var t = 0u; t < batch_size; t++) {
            let position = batch_end - 1u - t;
            var sum = no_fragment_grads();
            var any = false;
            // Past this invocation's last contributor nothing is left to do, but the subgroup
            // emission below needs every invocation, so no `continue`.
            if position < most {
                let splat = staged_splat(t);
                for (var p = 0u; p < PIXELS; p++) {
                    let d = splat.mean_opacity.xy - vec2<f32>(centre_x, centre_y[p]);
                    let sigma = splat_sigma(splat.conic, d);
                    let value = exp(-max(sigma, 0.0));
                    let alpha = min(ALPHA_MAX, splat.mean_opacity.z * value);
                    if position < contributed[p] && sigma >= 0.0 && alpha >= ALPHA_MIN {
                        any = true;
                        let one_over_rest = 1.0 / (1.0 - alpha);
                        transmittance[p] *= one_over_rest;
                        let grads = fragment_grads(
                            splat.mean_opacity, splat.conic, splat.colour, d, value, alpha, transmittance[p],
                            one_over_rest, behind[p], v_rgb[p], final_term[p],
                        );
                        sum = sum_fragment_grads(sum, grads);
                        behind[p] += splat.colour * (alpha * transmittance[p]);
                    }
                }
            }
            emit_fragment_grads(batch_gaussian[t], sum, any);
        }
        workgroupBarrier();
    }
}
