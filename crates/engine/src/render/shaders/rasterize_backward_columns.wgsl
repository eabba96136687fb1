// rasterize_backward.wgsl for software adapters: the same gradients, with each invocation walking a
// column of 8 pixels of the 16x16 tile (a workgroup of 16x2 columns), and each subgroup walking the
// tile's splats on its own, back to front from the last one its pixels composited, a chunk of one
// splat per lane at a time, only those that reach its block of pixels (rasterize_lane_chunk.wgsl).
// Needs subgroups. A CPU adapter's float atomics are compare-and-swap loops, so the 8 pixels'
// gradients are summed in registers and then over the subgroup (rasterize_grad_emit_shuffle.wgsl)
// before any atomic. Columns of 8 give the forward's 8x8 blocks and half the atomics and shuffles
// of columns of 4 (lavapipe, figurine at 256 px, 200 steps, best of 3 alternated runs: 9.4 against
// 13.2 ms a step); before the block test, 8 were slower than 4 (512 px, 200k random Gaussians: 467
// against 300 ms). The pixels are separate variables rather than an array, which lavapipe runs
// faster (198 against 210-216 ms). Bindings: rasterize_backward_common.wgsl; the fragment's
// gradients: rasterize_grad_fragment.wgsl.

const PIXELS: u32 = 8u;

// What one pixel's walk carries (a CPU adapter spills what does not fit its vector registers,
// so only this): the column's pixels share x, so their centres differ in y only.
struct PixelWalk {
    centre_y: f32,
    // The pixel's fragments are the first `contributed` of the tile's list.
    contributed: u32,
    v_rgb: vec3<f32>,
    final_term: f32,
    // In front of the current fragment, once it has been divided back out.
    transmittance: f32,
    // Colour composited behind the current fragment.
    behind: vec3<f32>,
}

fn pixel_walk(slot: u32, pixel: vec2<u32>) -> PixelWalk {
    var t_final = 1.0;
    var contributed = 0u;
    var v_out = vec4<f32>(0.0);
    if pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y {
        let index = slot_pixel_index(slot, pixel);
        t_final = final_transmittance[index];
        contributed = last_contributor[index];
        v_out = grad_image[index];
    }
    let final_term = final_alpha_term(t_final, v_out, uniforms.background.xyz);
    return PixelWalk(f32(pixel.y) + 0.5, contributed, v_out.xyz, final_term, t_final, vec3<f32>(0.0));
}

// The pixel's walk stepped back over the splat at list position `position`: a contributing
// fragment adds its gradients to `sum` and sets `contributes`.
fn step_back(
    walk: PixelWalk,
    splat: LaneSplat,
    centre_x: f32,
    position: u32,
    sum: ptr<function, FragmentGrads>,
    contributes: ptr<function, bool>,
) -> PixelWalk {
    let d = splat.mean_opacity.xy - vec2<f32>(centre_x, walk.centre_y);
    let sigma = splat_sigma(splat.conic, d);
    let value = exp(-max(sigma, 0.0));
    let alpha = min(ALPHA_MAX, splat.mean_opacity.z * value);
    if position >= walk.contributed || sigma < 0.0 || alpha < ALPHA_MIN {
        return walk;
    }
    var stepped = walk;
    let one_over_rest = 1.0 / (1.0 - alpha);
    stepped.transmittance *= one_over_rest;
    let grads = fragment_grads(
        splat.mean_opacity, splat.conic, splat.colour, d, value, alpha, stepped.transmittance,
        one_over_rest, walk.behind, walk.v_rgb, walk.final_term,
    );
    *sum = sum_fragment_grads(*sum, grads);
    *contributes = true;
    stepped.behind += splat.colour * (alpha * stepped.transmittance);
    return stepped;
}

// One-dimensional, as naga requires with subgroup_invocation_id: 16x2 columns.
@compute @workgroup_size(32)
fn rasterize_backward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) lanes: u32,
) {
    let tile = slot_tile(group);
    let column = vec2<u32>(local_index % TILE_SIZE, local_index / TILE_SIZE);
    let first_pixel = group.xy * TILE_SIZE + vec2<u32>(column.x, column.y * PIXELS);
    let centre_x = f32(first_pixel.x) + 0.5;
    var walk0 = pixel_walk(group.z, first_pixel);
    var walk1 = pixel_walk(group.z, first_pixel + vec2<u32>(0u, 1u));
    var walk2 = pixel_walk(group.z, first_pixel + vec2<u32>(0u, 2u));
    var walk3 = pixel_walk(group.z, first_pixel + vec2<u32>(0u, 3u));
    var walk4 = pixel_walk(group.z, first_pixel + vec2<u32>(0u, 4u));
    var walk5 = pixel_walk(group.z, first_pixel + vec2<u32>(0u, 5u));
    var walk6 = pixel_walk(group.z, first_pixel + vec2<u32>(0u, 6u));
    var walk7 = pixel_walk(group.z, first_pixel + vec2<u32>(0u, 7u));
    let most = max(max(max(walk0.contributed, walk1.contributed), max(walk2.contributed, walk3.contributed)),
        max(max(walk4.contributed, walk5.contributed), max(walk6.contributed, walk7.contributed)));
    let block = subgroup_block(
        vec2<f32>(centre_x, walk0.centre_y),
        vec2<f32>(centre_x, walk7.centre_y),
    );
    let start = tile_ranges[2u * tile];
    // The subgroup's walk: list positions [0, count), back to front.
    let count = subgroupMax(most);
    let chunk_lanes = min(lanes, CHUNK_LANES_MAX);
    for (var chunk = 0u; chunk < count; chunk += chunk_lanes) {
        // Lane i holds position count - 1 - (chunk + i).
        let own = load_lane_splat(start + count - 1u - min(chunk + lane, count - 1u));
        var pending = chunk_lanes_wanted(chunk + lane < count && splat_reaches_block(own, block), lane);
        while pending != 0u {
            let i = next_chunk_lane(&pending);
            let splat = splat_from_lane(own, i);
            let position = count - 1u - (chunk + i);
            var sum = no_fragment_grads();
            var contributes = false;
            if position < most {
                walk0 = step_back(walk0, splat, centre_x, position, &sum, &contributes);
                walk1 = step_back(walk1, splat, centre_x, position, &sum, &contributes);
                walk2 = step_back(walk2, splat, centre_x, position, &sum, &contributes);
                walk3 = step_back(walk3, splat, centre_x, position, &sum, &contributes);
                walk4 = step_back(walk4, splat, centre_x, position, &sum, &contributes);
                walk5 = step_back(walk5, splat, centre_x, position, &sum, &contributes);
                walk6 = step_back(walk6, splat, centre_x, position, &sum, &contributes);
                walk7 = step_back(walk7, splat, centre_x, position, &sum, &contributes);
            }
            emit_lane_sums(splat.gaussian, sum, contributes, lane, lanes);
        }
    }
}
