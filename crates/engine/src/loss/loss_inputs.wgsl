// The rendered image, the target image and the optional object-id mask of the target.

@group(0) @binding(1) var<storage, read> rendered: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> target_image: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> target_object_ids: array<u32>;

fn rendered_rgb(pixel: u32) -> vec3<f32> {
    return rendered[params.rendered_base + pixel].xyz;
}

// The target, zeroed outside the object when a mask is in use (the Segment-then-Splat object loss).
fn target_rgb(pixel: u32) -> vec3<f32> {
    let rgb = target_image[pixel].xyz;
    if params.use_mask != 0u && target_object_ids[pixel] != params.object_id {
        return vec3<f32>(0.0);
    }
    return rgb;
}
