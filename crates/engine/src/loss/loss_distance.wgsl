// Object losses only: for each tile, the Chebyshev distance in tiles to the nearest tile with
// content (loss_content.wgsl), capped at LOSS_SKIP_CAP. One invocation per tile.
//
// The passes skip the tiles beyond SKIP_REACH (loss_skip.wgsl says why that is exact).

@group(0) @binding(1) var<storage, read> tile_content: array<u32>;
@group(0) @binding(2) var<storage, read_write> tile_distance: array<u32>;

@compute @workgroup_size(64)
fn loss_tile_distance(@builtin(global_invocation_id) id: vec3<u32>) {
    let tiles = vec2<i32>(vec2<u32>(params.width, params.height) + LOSS_TILE - 1u) / i32(LOSS_TILE);
    if id.x >= u32(tiles.x * tiles.y) {
        return;
    }
    let tile = vec2<i32>(i32(id.x) % tiles.x, i32(id.x) / tiles.x);
    let cap = i32(LOSS_SKIP_CAP);
    var nearest = cap;
    for (var dy = -cap + 1; dy < cap; dy++) {
        for (var dx = -cap + 1; dx < cap; dx++) {
            let other = tile + vec2<i32>(dx, dy);
            if all(other >= vec2<i32>(0)) && all(other < tiles)
                && tile_content[other.y * tiles.x + other.x] != 0u {
                nearest = min(nearest, max(abs(dx), abs(dy)));
            }
        }
    }
    tile_distance[id.x] = u32(nearest);
}
