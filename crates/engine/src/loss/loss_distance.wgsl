// Object losses only: for each SKIP_CELL square, the Chebyshev distance in cells to the nearest
// cell with content (loss_content.wgsl), capped at LOSS_SKIP_CAP. One invocation per cell.
//
// The passes skip the cells beyond their reach (loss_skip.wgsl says why that is exact).

@group(0) @binding(1) var<storage, read> tile_content: array<u32>;
@group(0) @binding(2) var<storage, read_write> tile_distance: array<u32>;

@compute @workgroup_size(64)
fn loss_tile_distance(@builtin(global_invocation_id) id: vec3<u32>) {
    let cells = vec2<i32>(vec2<u32>(params.width, params.height) + SKIP_CELL - 1u) / i32(SKIP_CELL);
    if id.x >= u32(cells.x * cells.y) {
        return;
    }
    let cell = vec2<i32>(i32(id.x) % cells.x, i32(id.x) / cells.x);
    let cap = i32(LOSS_SKIP_CAP);
    var nearest = cap;
    for (var dy = -cap + 1; dy < cap; dy++) {
        for (var dx = -cap + 1; dx < cap; dx++) {
            let other = cell + vec2<i32>(dx, dy);
            if all(other >= vec2<i32>(0)) && all(other < cells)
                && tile_content[other.y * cells.x + other.x] != 0u {
                nearest = min(nearest, max(abs(dx), abs(dy)));
            }
        }
    }
    tile_distance[id.x] = u32(nearest);
}
