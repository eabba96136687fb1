// rasterize_forward.wgsl for software adapters: the same outputs, with each invocation
// compositing a column of 8 pixels of the 16x16 tile (a workgroup of 16x2 columns), and each
// subgroup walking the tile's splats on its own, a chunk of one splat per lane at a time, only
// those that reach its block of pixels (rasterize_lane_chunk.wgsl). Needs subgroups. Every splat
// read serves 8 pixels (lavapipe, 512 px, 200k random Gaussians: forward pass 902 ms per pixel,
// 460 ms with columns of 4, 384 ms with columns of 8, before lane chunks; with them, columns of
// 8 beat 4 by 72 to 76 ms). The 8 pixels are separate variables rather than an array, which
// lavapipe runs faster (71 against 74 ms). Bindings: rasterize_forward_common.wgsl.

const PIXELS: u32 = 8u;

// One pixel's compositing so far.
struct PixelComposite {
    centre: vec2<f32>,
    done: bool,
    transmittance: f32,
    rgb: vec3<f32>,
    depth_sum: f32,
    // Its fragments are the first `contributed` of the tile's list.
    contributed: u32,
}

fn pixel_composite(pixel: vec2<u32>) -> PixelComposite {
    let outside = pixel.x >= uniforms.image_size.x || pixel.y >= uniforms.image_size.y;
    return PixelComposite(vec2<f32>(pixel) + 0.5, outside, 1.0, vec3<f32>(0.0), 0.0, 0u);
}

// The pixel with the splat at list position `position` composited behind what it has; `live`
// counts the invocation's pixels not yet saturated.
fn composite(pixel: PixelComposite, splat: LaneSplat, position: u32, live: ptr<function, u32>) -> PixelComposite {
    let d = splat.mean_opacity.xy - pixel.centre;
    let sigma = splat_sigma(splat.conic, d);
    let alpha = min(ALPHA_MAX, splat.mean_opacity.z * exp(-sigma));
    if pixel.done || sigma < 0.0 || alpha < ALPHA_MIN {
        return pixel;
    }
    var next = pixel;
    let transmittance = pixel.transmittance * (1.0 - alpha);
    if transmittance <= TRANSMITTANCE_MIN {
        next.done = true;
        *live -= 1u;
        return next;
    }
    let weight = alpha * pixel.transmittance;
    next.rgb += splat.colour * weight;
    next.depth_sum += splat.mean_opacity.w * weight;
    next.transmittance = transmittance;
    next.contributed = position + 1u;
    return next;
}

fn write_pixel(slot: u32, pixel: vec2<u32>, composited: PixelComposite) {
    if pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y {
        let index = slot_pixel_index(slot, pixel);
        let t = composited.transmittance;
        image[index] = vec4<f32>(composited.rgb + t * uniforms.background.xyz, 1.0 - t);
        final_transmittance[index] = t;
        last_contributor[index] = composited.contributed;
        depth[index] = composited.depth_sum;
    }
}

// One-dimensional, as naga requires with subgroup_invocation_id: 16x2 columns.
@compute @workgroup_size(32)
fn rasterize_forward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) lanes: u32,
) {
    let tile = slot_tile(group);
    let column = vec2<u32>(local_index % TILE_SIZE, local_index / TILE_SIZE);
    let first_pixel = group.xy * TILE_SIZE + vec2<u32>(column.x, column.y * PIXELS);
    let start = tile_ranges[2u * tile];
    let end = tile_ranges[2u * tile + 1u];
    var p0 = pixel_composite(first_pixel);
    var p1 = pixel_composite(first_pixel + vec2<u32>(0u, 1u));
    var p2 = pixel_composite(first_pixel + vec2<u32>(0u, 2u));
    var p3 = pixel_composite(first_pixel + vec2<u32>(0u, 3u));
    var p4 = pixel_composite(first_pixel + vec2<u32>(0u, 4u));
    var p5 = pixel_composite(first_pixel + vec2<u32>(0u, 5u));
    var p6 = pixel_composite(first_pixel + vec2<u32>(0u, 6u));
    var p7 = pixel_composite(first_pixel + vec2<u32>(0u, 7u));
    var live = u32(!p0.done) + u32(!p1.done) + u32(!p2.done) + u32(!p3.done) + u32(!p4.done)
        + u32(!p5.done) + u32(!p6.done) + u32(!p7.done);
    let block = subgroup_block(p0.centre, p7.centre);
    let chunk_lanes = min(lanes, CHUNK_LANES_MAX);
    for (var chunk = start; chunk < end; chunk += chunk_lanes) {
        if !subgroupAny(live > 0u) {
            break;
        }
        // Front to back: lane i holds intersection chunk + i.
        let own = load_lane_splat(min(chunk + lane, end - 1u));
        var pending = chunk_lanes_wanted(chunk + lane < end && splat_reaches_block(own, block), lane);
        while pending != 0u {
            let i = next_chunk_lane(&pending);
            let splat = splat_from_lane(own, i);
            if live == 0u {
                continue;
            }
            let position = chunk + i - start;
            p0 = composite(p0, splat, position, &live);
            p1 = composite(p1, splat, position, &live);
            p2 = composite(p2, splat, position, &live);
            p3 = composite(p3, splat, position, &live);
            p4 = composite(p4, splat, position, &live);
            p5 = composite(p5, splat, position, &live);
            p6 = composite(p6, splat, position, &live);
            p7 = composite(p7, splat, position, &live);
        }
    }
    write_pixel(group.z, first_pixel, p0);
    write_pixel(group.z, first_pixel + vec2<u32>(0u, 1u), p1);
    write_pixel(group.z, first_pixel + vec2<u32>(0u, 2u), p2);
    write_pixel(group.z, first_pixel + vec2<u32>(0u, 3u), p3);
    write_pixel(group.z, first_pixel + vec2<u32>(0u, 4u), p4);
    write_pixel(group.z, first_pixel + vec2<u32>(0u, 5u), p5);
    write_pixel(group.z, first_pixel + vec2<u32>(0u, 6u), p6);
    write_pixel(group.z, first_pixel + vec2<u32>(0u, 7u), p7);
    // The column lies in one occupancy square (PIXELS == OCCUPANCY_CELL, columns start at
    // multiples of it); pixels outside the image never composite, so their colour is zero.
    if uniforms.mark_occupancy != 0u {
        let zero = vec3<f32>(0.0);
        if any(p0.rgb != zero) || any(p1.rgb != zero) || any(p2.rgb != zero)
            || any(p3.rgb != zero) || any(p4.rgb != zero) || any(p5.rgb != zero)
            || any(p6.rgb != zero) || any(p7.rgb != zero) {
            mark_occupied(group.z, first_pixel);
        }
    }
}

const_assert PIXELS == OCCUPANCY_CELL && TILE_SIZE % OCCUPANCY_CELL == 0u;
