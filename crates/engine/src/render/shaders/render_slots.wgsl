// Batched object renders (object_batch.rs) stack their slots along the workgroup grid's z: slot
// z's tiles and pixels follow those of the slots before it, so a single render is slot 0 and
// reads exactly what it did before batching.
fn slot_tile(group: vec3<u32>) -> u32 {
    return (group.z * uniforms.tile_grid.y + group.y) * uniforms.tile_grid.x + group.x;
}

fn slot_pixel_index(slot: u32, pixel: vec2<u32>) -> u32 {
    return (slot * uniforms.image_size.y + pixel.y) * uniforms.image_size.x + pixel.x;
}
