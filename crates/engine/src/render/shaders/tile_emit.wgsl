// One invocation per Gaussian in depth order: writes its (tile id, Gaussian) intersections at its
// scanned offset (tile_emit_splat.wgsl). Entries past the capacity are dropped (the host sees the
// unclamped total and grows the buffers).

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> depth_values: array<u32>;
@group(0) @binding(2) var<storage, read> tile_offsets: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> intersection_tiles: array<u32>;
@group(0) @binding(5) var<storage, read_write> intersection_gaussians: array<u32>;

const GROUP_SIZE: u32 = 256u;

@compute @workgroup_size(256)
fn tile_emit(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let j = flat_index(gid, num_groups, GROUP_SIZE);
    if j >= uniforms.gaussian_count {
        return;
    }
    let end = min(tile_offsets[j + 1u], uniforms.intersection_capacity);
    emit_splat_tiles(depth_values[j], 0u, tile_offsets[j], end);
}
