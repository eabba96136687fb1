// Backward of rasterize_forward: one 16x16 workgroup per tile; each pixel walks its splats back to
// front from its last contributor, recovering the transmittance before each fragment by division
// (as 3DGS/gsplat do), and adds d loss / d (mean2d, conic, colour, opacity) and |d loss / d mean2d|
// into grad_projected with float atomics (native or CAS: rasterize_grad_atomics_*.wgsl), summed
// over the subgroup first on hardware with subgroups (rasterize_grad_emit_*.wgsl). The loop
// over a batch's splats stays uniform (no early `continue`) so the subgroup sums are legal.
// Bindings: rasterize_backward_common.wgsl; batch staging: rasterize_batch.wgsl; the fragment's
// gradients: rasterize_grad_fragment.wgsl.

var<workgroup> batch_gaussian: array<u32, 256>;
var<workgroup> range_start: u32;
var<workgroup> longest: atomic<u32>;
var<workgroup> longest_snapshot: u32;

// The tile's first intersection and the most intersections any of its pixels walks (each
// invocation passes its pixel's count), the same in every invocation.
fn tile_walk(tile: u32, local_index: u32, contributed: u32) -> vec2<u32> {
    if local_index == 0u {
        range_start = tile_ranges[2u * tile];
        atomicStore(&longest, 0u);
    }
    workgroupBarrier();
    atomicMax(&longest, contributed);
    workgroupBarrier();
    if local_index == 0u {
        longest_snapshot = atomicLoad(&longest);
    }
    return vec2<u32>(workgroupUniformLoad(&range_start), workgroupUniformLoad(&longest_snapshot));
}

// Stages splat `slot` of a back-to-front batch whose last range position is `batch_end - 1`.
fn stage_splat_backwards(start: u32, batch_end: u32, slot: u32) {
    let gaussian = intersection_gaussians[start + batch_end - 1u - slot];
    batch_gaussian[slot] = gaussian;
    stage_projected(slot, gaussian);
}

@compute @workgroup_size(16, 16)
fn rasterize_backward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tile = slot_tile(group);
    let pixel = group.xy * TILE_SIZE + local.xy;
    let inside = pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y;
    let centre = vec2<f32>(pixel) + 0.5;
    let pixel_index = slot_pixel_index(group.z, pixel);

    var t_final = 1.0;
    var contributed = 0u;
    var v_out = vec4<f32>(0.0);
    if inside {
        t_final = final_transmittance[pixel_index];
        contributed = last_contributor[pixel_index];
        v_out = grad_image[pixel_index];
    }
    let walk = tile_walk(tile, local_index, contributed);
    let start = walk.x;
    let count = walk.y;
    let batches = (count + BATCH - 1u) / BATCH;
    let final_term = final_alpha_term(t_final, v_out, uniforms.background.xyz);

    var transmittance = t_final;
    var behind = vec3<f32>(0.0);
    for (var b = 0u; b < batches; b++) {
        // Batch b holds range positions [count - (b + 1) * BATCH, count - b * BATCH), back to front.
        let batch_end = count - b * BATCH;
        let batch_size = min(BATCH, batch_end);
        if local_index < batch_size {
            stage_splat_backwards(start, batch_end, local_index);
        }
        workgroupBarrier();
        for (var t = 0u; t < batch_size; t++) {
            let position = batch_end - 1u - t;
            let mean_opacity = batch_mean_opacity[t];
            let conic = batch_conic[t].xyz;
            let d = mean_opacity.xy - centre;
            let sigma = splat_sigma(conic, d);
            let value = exp(-max(sigma, 0.0));
            let alpha = min(ALPHA_MAX, mean_opacity.z * value);
            let contributes = position < contributed && sigma >= 0.0 && alpha >= ALPHA_MIN;
            var grads = no_fragment_grads();
            if contributes {
                let one_over_rest = 1.0 / (1.0 - alpha);
                transmittance *= one_over_rest;
                let colour = batch_colour[t].xyz;
                grads = fragment_grads(
                    mean_opacity, conic, colour, d, value, alpha, transmittance, one_over_rest,
                    behind, v_out.xyz, final_term,
                );
                behind += colour * (alpha * transmittance);
            }
            emit_fragment_grads(batch_gaussian[t], grads, contributes);
        }
        workgroupBarrier();
    }
}
