// The partial-mask filter's overlap counts, per object slot of a batch of object renders: pixels
// where the slot's render covers (alpha > 0.5) and its mask holds the object (intersection), and
// where either does (union). The filter divides them on the CPU, so only two numbers per
// (object, view) pair leave the GPU instead of the slot's whole image.

struct IouUniforms {
    pixel_count: u32,
    slot_count: u32,
    // Index of the batch's first slot in `counts` (in pairs).
    first_pair: u32,
    _pad: u32,
}

// Pixels each invocation counts before its two atomics.
const RUN: u32 = 64u;

@group(0) @binding(0) var<uniform> uniforms: IouUniforms;
// The batch's images, slot after slot (`pixel_count` rgba pixels each).
@group(0) @binding(1) var<storage, read> images: array<vec4<f32>>;
// The view's object ids per level (0 = none), one u32 per pixel.
@group(0) @binding(2) var<storage, read> ids_small: array<u32>;
@group(0) @binding(3) var<storage, read> ids_middle: array<u32>;
@group(0) @binding(4) var<storage, read> ids_large: array<u32>;
// Per slot: (level index, object id).
@group(0) @binding(5) var<storage, read> slots: array<vec2<u32>>;
// Per pair: intersection, union.
@group(0) @binding(6) var<storage, read_write> counts: array<atomic<u32>>;

fn mask_id(level: u32, pixel: u32) -> u32 {
    if level == 0u {
        return ids_small[pixel];
    }
    if level == 1u {
        return ids_middle[pixel];
    }
    return ids_large[pixel];
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let slot = gid.y;
    let start = gid.x * RUN;
    if slot >= uniforms.slot_count || start >= uniforms.pixel_count {
        return;
    }
    let end = min(start + RUN, uniforms.pixel_count);
    let level = slots[slot].x;
    let id = slots[slot].y;
    let image_start = slot * uniforms.pixel_count;
    var intersection = 0u;
    var union_count = 0u;
    for (var pixel = start; pixel < end; pixel++) {
        let rendered = images[image_start + pixel].w > 0.5;
        let masked = mask_id(level, pixel) == id;
        intersection += u32(rendered && masked);
        union_count += u32(rendered || masked);
    }
    if union_count > 0u {
        let pair = uniforms.first_pair + slot;
        atomicAdd(&counts[2u * pair], intersection);
        atomicAdd(&counts[2u * pair + 1u], union_count);
    }
}
