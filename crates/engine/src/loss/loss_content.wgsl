// Object losses only (use_mask = 1): whether each LOSS_TILE square holds content, i.e. any pixel
// whose rendered or (masked) target colour is non-zero. One workgroup per tile. An object's
// render and mask usually cover a small part of the image, and where both are zero over the
// whole SSIM reach the loss and its gradient are exactly zero (loss_distance.wgsl).

// Zeroed before the pass; a pixel with content marks its tile. No workgroup memory or barriers:
// a CPU adapter pays for a barrier in every workgroup.
@group(0) @binding(4) var<storage, read_write> tile_content: array<atomic<u32>>;

@compute @workgroup_size(LOSS_TILE, LOSS_TILE)
fn loss_tile_content(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
) {
    let x = i32(id.x);
    let y = i32(id.y);
    if inside(x, y) {
        let pixel = pixel_index(x, y);
        if any(rendered_rgb(pixel) != vec3<f32>(0.0)) || any(target_rgb(pixel) != vec3<f32>(0.0)) {
            atomicStore(&tile_content[workgroup.x + workgroup.y * workgroups.x], 1u);
        }
    }
}
