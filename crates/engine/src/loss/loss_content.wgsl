// Object losses only (use_mask = 1): whether each LOSS_TILE square holds content, i.e. any pixel
// whose rendered or (masked) target colour is non-zero. One workgroup per tile. An object's
// render and mask usually cover a small part of the image, and where both are zero over the
// whole SSIM reach the loss and its gradient are exactly zero (loss_distance.wgsl).

// Zeroed before the pass; a row with content marks its tile. No workgroup memory or barriers:
// a CPU adapter pays for a barrier in every workgroup.
@group(0) @binding(4) var<storage, read_write> tile_content: array<atomic<u32>>;

// One invocation per row of the tile, so a tile costs at most LOSS_TILE atomic stores (a CPU
// adapter issues atomics lane by lane), and a row stops at its first content pixel.
@compute @workgroup_size(LOSS_TILE)
fn loss_tile_content(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) row: u32,
) {
    let y = i32(workgroup.y * LOSS_TILE + row);
    let start = i32(workgroup.x * LOSS_TILE);
    if y >= i32(params.height) {
        return;
    }
    let end = min(start + i32(LOSS_TILE), i32(params.width));
    var content = false;
    for (var x = start; x < end; x++) {
        let pixel = pixel_index(x, y);
        if any(rendered_rgb(pixel) != vec3<f32>(0.0)) || any(target_rgb(pixel) != vec3<f32>(0.0)) {
            content = true;
            break;
        }
    }
    if content {
        atomicStore(&tile_content[workgroup.x + workgroup.y * workgroups.x], 1u);
    }
}
