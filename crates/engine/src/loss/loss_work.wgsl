// Which (slot, tile) a workgroup of the four SSIM passes computes. An unmasked loss dispatches
// one workgroup per tile; a batch of object losses dispatches one per item of a work list
// (loss_work_lists.wgsl) of the tiles within the pass's reach of each slot's content, so the
// tiles beyond it cost nothing. Expects a `work_items` binding.

// Sets `slot` and returns the tile's coordinates.
fn enter_tile(workgroup: vec3<u32>) -> vec2<u32> {
    if params.use_mask == 0u {
        slot = 0u;
        return workgroup.xy;
    }
    let item = work_items[workgroup.x];
    slot = item.x;
    return vec2<u32>(item.y % params.tiles_x, item.y / params.tiles_x);
}
