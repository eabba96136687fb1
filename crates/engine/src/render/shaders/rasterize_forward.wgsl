// Rasterisation: one 16x16 workgroup per tile, one invocation per pixel. The tile's splats (in
// depth order) are loaded in batches of 256 into workgroup memory and composited front to back;
// the workgroup stops when every pixel is saturated.
//
// Per pixel outputs: image (rgb with background, alpha), final transmittance, and the number of
// the tile's intersections processed up to the last one that contributed (backward starts there).
// Bindings: rasterize_forward_common.wgsl; batch staging: rasterize_batch.wgsl.

var<workgroup> range_start: u32;
var<workgroup> range_end: u32;
// Invocations with a pixel still unsaturated, counted before each batch.
var<workgroup> active_invocations: atomic<u32>;
var<workgroup> active_snapshot: u32;

// Stages splat `slot` of the batch starting at intersection `first`.
fn stage_splat(first: u32, slot: u32) {
    stage_projected(slot, intersection_gaussians[first + slot]);
}

// The tile's [start, end) in the sorted intersections, the same in every invocation.
fn load_tile_range(tile: u32, local_index: u32) -> vec2<u32> {
    if local_index == 0u {
        range_start = tile_ranges[2u * tile];
        range_end = tile_ranges[2u * tile + 1u];
    }
    return vec2<u32>(workgroupUniformLoad(&range_start), workgroupUniformLoad(&range_end));
}

// Whether any invocation of the workgroup is `still_working` (called by all, between batches).
fn any_invocation_active(still_working: bool, local_index: u32) -> bool {
    if local_index == 0u {
        atomicStore(&active_invocations, 0u);
    }
    workgroupBarrier();
    if still_working {
        atomicAdd(&active_invocations, 1u);
    }
    workgroupBarrier();
    if local_index == 0u {
        active_snapshot = atomicLoad(&active_invocations);
    }
    return workgroupUniformLoad(&active_snapshot) != 0u;
}

@compute @workgroup_size(16, 16)
fn rasterize_forward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tile = slot_tile(group);
    let pixel = group.xy * TILE_SIZE + local.xy;
    let inside = pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y;
    let centre = vec2<f32>(pixel) + 0.5;
    let range = load_tile_range(tile, local_index);
    let start = range.x;
    let end = range.y;
    let batches = (end - start + BATCH - 1u) / BATCH;

    var done = !inside;
    var transmittance = 1.0;
    var rgb = vec3<f32>(0.0);
    var depth_sum = 0.0;
    var contributed = 0u;
    for (var b = 0u; b < batches; b++) {
        if !any_invocation_active(!done, local_index) {
            break;
        }
        if start + b * BATCH + local_index < end {
            stage_splat(start + b * BATCH, local_index);
        }
        workgroupBarrier();
        let batch_size = min(BATCH, end - start - b * BATCH);
        for (var t = 0u; t < batch_size; t++) {
            if done {
                break;
            }
            let mean_opacity = batch_mean_opacity[t];
            let conic = batch_conic[t].xyz;
            let d = mean_opacity.xy - centre;
            let sigma = splat_sigma(conic, d);
            if sigma < 0.0 {
                continue;
            }
            let alpha = min(ALPHA_MAX, mean_opacity.z * exp(-sigma));
            if alpha < ALPHA_MIN {
                continue;
            }
            let next = transmittance * (1.0 - alpha);
            if next <= TRANSMITTANCE_MIN {
                done = true;
                break;
            }
            let weight = alpha * transmittance;
            rgb += batch_colour[t].xyz * weight;
            depth_sum += mean_opacity.w * weight;
            transmittance = next;
            contributed = b * BATCH + t + 1u;
        }
        workgroupBarrier();
    }
    if inside {
        let index = slot_pixel_index(group.z, pixel);
        image[index] = vec4<f32>(rgb + transmittance * uniforms.background.xyz, 1.0 - transmittance);
        final_transmittance[index] = transmittance;
        last_contributor[index] = contributed;
        depth[index] = depth_sum;
        if uniforms.mark_occupancy != 0u && any(rgb != vec3<f32>(0.0)) {
            mark_occupied(group.z, pixel);
        }
    }
}
