// Writes one splat's (key, Gaussian) intersections into [offset, end): the tiles its footprint
// touches (tile_footprint.wgsl) in row-major order, each keyed `key_base + tile id`. Shared by
// tile_emit.wgsl (one render: key_base 0) and object_tile_emit.wgsl (batched object renders:
// key_base = slot x tiles). Expects `projected`, `intersection_tiles` and
// `intersection_gaussians` bindings.
fn emit_splat_tiles(gaussian: u32, key_base: u32, first: u32, end: u32) {
    var offset = first;
    if offset >= end {
        return;
    }
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
            intersection_tiles[offset] = key_base + row * uniforms.tile_grid.x + x;
            intersection_gaussians[offset] = gaussian;
            offset += 1u;
        }
    }
    // Should the compiler have rounded the footprint differently in project_forward, so that it
    // counted a tile this loop left out, the slot gets a tile the footprint misses: its pixels
    // all fail the alpha threshold, so the rasterizer passes over it (rather than over a stale
    // entry). Tiles found here but not counted there are dropped above, as unseen.
    for (; offset < end; offset++) {
        intersection_tiles[offset] = key_base + missed;
        intersection_gaussians[offset] = gaussian;
    }
}
