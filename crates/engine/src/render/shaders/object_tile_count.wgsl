// Batched object renders, step 1 (object_batch.rs): one invocation per Gaussian in the depth
// order of the step's full render, which this reuses: the Gaussian's tile count (from that
// render's projection; 0 when culled) times the number of object slots it belongs to. The scan
// of these gives every (slot, Gaussian) run an intersection offset in depth order.
//
// slots[s] = (level, object id); a Gaussian belongs to slot s when its id at that level is the
// slot's. A Gaussian can belong to one slot per level.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> depth_values: array<u32>;
@group(0) @binding(2) var<storage, read> tile_counts: array<u32>;
@group(0) @binding(3) var<storage, read> object_ids: array<u32>;
@group(0) @binding(4) var<storage, read> slots: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> tile_counts_in_depth_order: array<u32>;

const GROUP_SIZE: u32 = 256u;

@compute @workgroup_size(256)
fn object_tile_count(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let j = flat_index(gid, num_groups, GROUP_SIZE);
    if j >= uniforms.gaussian_count {
        return;
    }
    let gaussian = depth_values[j];
    var memberships = 0u;
    for (var s = 0u; s < arrayLength(&slots); s++) {
        let slot = slots[s];
        memberships += u32(object_ids[3u * gaussian + slot.x] == slot.y);
    }
    tile_counts_in_depth_order[j] = tile_counts[gaussian] * memberships;
}
