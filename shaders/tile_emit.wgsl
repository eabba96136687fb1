// One invocation per Gaussian in depth order: writes its (tile id, Gaussian) intersections at its
// scanned offset, tiles in row-major order. Entries past the capacity are dropped (the host sees
// the unclamped total and grows the buffers).

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
    var offset = tile_offsets[j];
    let end = min(tile_offsets[j + 1u], uniforms.intersection_capacity);
    if offset >= end {
        return;
    }
    let gaussian = depth_values[j];
    let mean2d = projected[3u * gaussian].xy;
    let radius = projected[3u * gaussian + 1u].w;
    let grid = vec2<f32>(uniforms.tile_grid);
    let tile_min = vec2<u32>(clamp(floor((mean2d - radius) / f32(TILE_SIZE)), vec2<f32>(0.0), grid));
    let tile_max = vec2<u32>(clamp(ceil((mean2d + radius) / f32(TILE_SIZE)), vec2<f32>(0.0), grid));
    for (var y = tile_min.y; y < tile_max.y; y++) {
        for (var x = tile_min.x; x < tile_max.x; x++) {
            if offset >= end {
                return;
            }
            intersection_tiles[offset] = y * uniforms.tile_grid.x + x;
            intersection_gaussians[offset] = gaussian;
            offset += 1u;
        }
    }
}
