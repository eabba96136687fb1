// The rendered images and the target image (the id maps: loss_id_maps.wgsl).

@group(0) @binding(1) var<storage, read> rendered: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> target_image: array<vec4<f32>>;

fn rendered_rgb(pixel: u32) -> vec3<f32> {
    return rendered[(params.first_rendered + slot) * pixel_count() + pixel].xyz;
}

// The target, zeroed outside the slot's object for an object loss (Segment then Splat). The
// mask first: most of an object loss's pixels are outside its object and need no colour read.
fn target_rgb(pixel: u32) -> vec3<f32> {
    if params.use_mask != 0u && !in_slot_object(pixel) {
        return vec3<f32>(0.0);
    }
    return target_image[pixel].xyz;
}
