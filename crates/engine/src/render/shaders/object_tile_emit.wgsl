// Batched object renders, step 2: one invocation per Gaussian in depth order; for each object
// slot it belongs to (object_tile_count.wgsl), in slot order, its footprint's tiles keyed
// `slot x tiles + tile`, at its scanned offset. Sorting by that key keeps depth order within each
// (slot, tile), so every slot's tile lists are what a render of that object alone would build.
// Entries past the capacity are dropped.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> depth_values: array<u32>;
@group(0) @binding(2) var<storage, read> tile_offsets: array<u32>;
@group(0) @binding(3) var<storage, read> tile_counts: array<u32>;
@group(0) @binding(4) var<storage, read> object_ids: array<u32>;
@group(0) @binding(5) var<storage, read> slots: array<vec2<u32>>;
@group(0) @binding(6) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> intersection_tiles: array<u32>;
@group(0) @binding(8) var<storage, read_write> intersection_gaussians: array<u32>;

const GROUP_SIZE: u32 = 256u;

@compute @workgroup_size(256)
fn object_tile_emit(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let j = flat_index(gid, num_groups, GROUP_SIZE);
    if j >= uniforms.gaussian_count {
        return;
    }
    let gaussian = depth_values[j];
    let tiles = tile_counts[gaussian];
    if tiles == 0u {
        return;
    }
    let tiles_per_slot = uniforms.tile_grid.x * uniforms.tile_grid.y;
    var offset = tile_offsets[j];
    for (var s = 0u; s < arrayLength(&slots); s++) {
        let slot = slots[s];
        if object_ids[3u * gaussian + slot.x] != slot.y {
            continue;
        }
        let end = min(offset + tiles, uniforms.intersection_capacity);
        emit_splat_tiles(gaussian, s * tiles_per_slot, offset, end);
        offset += tiles;
    }
}
