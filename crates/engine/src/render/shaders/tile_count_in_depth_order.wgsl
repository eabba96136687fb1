// Gathers each Gaussian's tile count in depth order, so the scan gives every Gaussian an
// intersection offset that already respects depth order.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> depth_values: array<u32>;
@group(0) @binding(2) var<storage, read> tile_counts: array<u32>;
@group(0) @binding(3) var<storage, read_write> tile_counts_in_depth_order: array<u32>;

const GROUP_SIZE: u32 = 256u;

@compute @workgroup_size(256)
fn tile_count_in_depth_order(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let j = flat_index(gid, num_groups, GROUP_SIZE);
    if j >= uniforms.gaussian_count {
        return;
    }
    tile_counts_in_depth_order[j] = tile_counts[depth_values[j]];
}
