// One invocation per Gaussian in depth order: writes its (tile id, Gaussian) intersections at its
// scanned offset, for the tiles its footprint touches (tile_footprint.wgsl) in row-major order.
// Entries past the capacity are dropped (the host sees the unclamped total and grows the
// buffers).

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
    let mean_opacity = projected[3u * gaussian];
    let conic = projected[3u * gaussian + 1u].xyz;
    let footprint = splat_footprint(mean_opacity.xy, conic, footprint_sigma(mean_opacity.z));
    let rows = footprint_tile_rows(footprint, uniforms.tile_grid);
    // A tile the footprint misses, for the padding below (none only when it covers the grid).
    var missed = 0u;
    if rows.x > 0u {
        missed = (rows.x - 1u) * uniforms.tile_grid.x;
    } else if rows.y < uniforms.tile_grid.y {
        missed = rows.y * uniforms.tile_grid.x;
    }
    for (var row = rows.x; row < rows.y; row++) {
        let columns = footprint_tile_columns(footprint, row, uniforms.tile_grid.x);
        if columns.x > 0u {
            missed = row * uniforms.tile_grid.x;
        } else if columns.y < uniforms.tile_grid.x {
            missed = row * uniforms.tile_grid.x + uniforms.tile_grid.x - 1u;
        }
        for (var x = columns.x; x < columns.y; x++) {
            if offset >= end {
                return;
            }
            intersection_tiles[offset] = row * uniforms.tile_grid.x + x;
            intersection_gaussians[offset] = gaussian;
            offset += 1u;
        }
    }
    // Should the compiler have rounded the footprint differently in project_forward, so that it
    // counted a tile this loop left out, the slot gets a tile the footprint misses: its pixels
    // all fail the alpha threshold, so the rasterizer passes over it (rather than over a stale
    // entry). Tiles found here but not counted there are dropped above, as unseen.
    for (; offset < end; offset++) {
        intersection_tiles[offset] = missed;
        intersection_gaussians[offset] = gaussian;
    }
}
