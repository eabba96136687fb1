// Which loss tiles a pass computes (loss_distance.wgsl): all of them for the full render's loss;
// for an object loss, those within `reach` tiles of content (the gradient pass 1, the horizontal
// partials 2, the per-pixel pass 3, the horizontal moments 4). Expects a `tile_distance`
// binding.

const LOSS_SKIP_CAP: u32 = 5u;

fn tile_in_reach(x: i32, y: i32, reach: u32) -> bool {
    if params.use_mask == 0u {
        return true;
    }
    let tiles_x = (params.width + LOSS_TILE - 1u) / LOSS_TILE;
    let tile = u32(y) / LOSS_TILE * tiles_x + u32(x) / LOSS_TILE;
    return tile_distance[tile] <= reach;
}
