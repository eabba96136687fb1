// The rendered images, the target image and the object-id maps the slots' masks read.

@group(0) @binding(1) var<storage, read> rendered: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> target_image: array<vec4<f32>>;
// One map per level at most (a batch's slots may come from any level); the host binds the first
// map in the places of absent ones.
@group(0) @binding(3) var<storage, read> id_map_0: array<u32>;
@group(0) @binding(4) var<storage, read> id_map_1: array<u32>;
@group(0) @binding(5) var<storage, read> id_map_2: array<u32>;

fn rendered_rgb(pixel: u32) -> vec3<f32> {
    return rendered[(params.first_rendered + slot) * pixel_count() + pixel].xyz;
}

fn object_id_at(map: u32, pixel: u32) -> u32 {
    switch map {
        case 1u: {
            return id_map_1[pixel];
        }
        case 2u: {
            return id_map_2[pixel];
        }
        default: {
            return id_map_0[pixel];
        }
    }
}

// The target, zeroed outside the slot's object for an object loss (Segment then Splat). The
// mask first: most of an object loss's pixels are outside its object and need no colour read.
fn target_rgb(pixel: u32) -> vec3<f32> {
    if params.use_mask != 0u {
        let mask = params.slots[slot];
        if object_id_at(mask.x, pixel) != mask.y {
            return vec3<f32>(0.0);
        }
    }
    return target_image[pixel].xyz;
}
