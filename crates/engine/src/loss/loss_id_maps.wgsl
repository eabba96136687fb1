// The object-id maps the slots' masks read (object losses).

// One map per level at most (a batch's slots may come from any level); the host binds the first
// map in the places of absent ones.
@group(0) @binding(3) var<storage, read> id_map_0: array<u32>;
@group(0) @binding(4) var<storage, read> id_map_1: array<u32>;
@group(0) @binding(5) var<storage, read> id_map_2: array<u32>;

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

// Whether `pixel` belongs to this invocation's slot's object.
fn in_slot_object(pixel: u32) -> bool {
    let mask = params.slots[slot];
    return object_id_at(mask.x, pixel) == mask.y;
}
