// Object losses only: for each slot's SKIP_CELL squares, the Chebyshev distance in cells to the
// nearest cell with content (loss_content.wgsl), capped at LOSS_SKIP_CAP; and the work lists of
// the SSIM passes: the (slot, tile) pairs with a cell within reach 1 (the first two passes) and
// within reach 2 (the last two), appended in any order, their counts the x of two indirect
// dispatches. One invocation per tile (x) and slot (y).
//
// The passes skip the cells beyond their reach (loss_skip.wgsl says why that is exact); the
// lists spare them even the workgroups of tiles where every cell is skipped.

@group(0) @binding(1) var<storage, read> tile_content: array<u32>;
@group(0) @binding(2) var<storage, read_write> tile_distance: array<u32>;
// Two indirect dispatches' arguments: (near count, 1, 1, far count, 1, 1), the counts zeroed
// before the pass.
@group(0) @binding(3) var<storage, read_write> work_counts: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> near_items: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> far_items: array<vec2<u32>>;

const CELLS_PER_TILE: u32 = LOSS_TILE / SKIP_CELL;

// The distance from `cell` to the nearest content cell of this slot, capped.
fn content_distance(cell: vec2<i32>, cells: vec2<i32>) -> u32 {
    let cap = i32(LOSS_SKIP_CAP);
    let first = slot * u32(cells.x * cells.y);
    var nearest = cap;
    for (var dy = -cap + 1; dy < cap; dy++) {
        for (var dx = -cap + 1; dx < cap; dx++) {
            let other = cell + vec2<i32>(dx, dy);
            if all(other >= vec2<i32>(0)) && all(other < cells)
                && tile_content[first + u32(other.y * cells.x + other.x)] != 0u {
                nearest = min(nearest, max(abs(dx), abs(dy)));
            }
        }
    }
    return u32(nearest);
}

@compute @workgroup_size(64)
fn loss_work_lists(@builtin(global_invocation_id) id: vec3<u32>) {
    slot = id.y;
    let tiles_y = (params.height + LOSS_TILE - 1u) / LOSS_TILE;
    if id.x >= params.tiles_x * tiles_y {
        return;
    }
    let tile = vec2<u32>(id.x % params.tiles_x, id.x / params.tiles_x);
    let cells = vec2<i32>(cell_grid());
    var nearest = LOSS_SKIP_CAP;
    for (var part = 0u; part < CELLS_PER_TILE * CELLS_PER_TILE; part++) {
        let cell = vec2<i32>(tile * CELLS_PER_TILE + vec2<u32>(part % CELLS_PER_TILE, part / CELLS_PER_TILE));
        if all(cell < cells) {
            let distance = content_distance(cell, cells);
            tile_distance[slot * u32(cells.x * cells.y) + u32(cell.y * cells.x + cell.x)] = distance;
            nearest = min(nearest, distance);
        }
    }
    let item = vec2<u32>(slot, id.x);
    if nearest <= REACH_SSIM {
        near_items[atomicAdd(&work_counts[0], 1u)] = item;
    }
    if nearest <= REACH_GRADIENT {
        far_items[atomicAdd(&work_counts[3], 1u)] = item;
    }
}

const_assert REACH_ROW_MOMENTS <= REACH_SSIM && REACH_ROW_PARTIALS <= REACH_GRADIENT;
