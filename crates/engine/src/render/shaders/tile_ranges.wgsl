// One invocation per intersection (sorted by tile): marks where each tile's run starts and ends.
// tile_ranges (2 u32 per tile: start, end) must be zero before.

@group(0) @binding(0) var<storage, read> counts: array<u32>;
@group(0) @binding(1) var<storage, read> intersection_tiles: array<u32>;
@group(0) @binding(2) var<storage, read_write> tile_ranges: array<u32>;

const GROUP_SIZE: u32 = 256u;

@compute @workgroup_size(256)
fn tile_ranges_from_sorted(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let i = gid.x + gid.y * num_groups.x * GROUP_SIZE;
    let count = counts[1];
    if i >= count {
        return;
    }
    let tile = intersection_tiles[i];
    if i == 0u || intersection_tiles[i - 1u] != tile {
        tile_ranges[2u * tile] = i;
    }
    if i + 1u == count || intersection_tiles[i + 1u] != tile {
        tile_ranges[2u * tile + 1u] = i + 1u;
    }
}
