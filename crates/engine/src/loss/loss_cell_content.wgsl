// Object losses whose renders marked their occupancy (the batched object renders do): whether
// each SKIP_CELL square of each slot holds content, from that occupancy and the masks' cell maps
// (`object_cell_map` in loss.rs) instead of reading every pixel (loss_content.wgsl). A square
// holds content where the slot's render is occupied or its mask holds the slot's object. The
// latter also counts squares whose object pixels have a black target, which only adds work:
// skipping stays exact (loss_skip.wgsl). One invocation per square (x) and slot (y); each writes
// its square, so the buffer needs no clearing.

@group(0) @binding(1) var<storage, read> occupancy: array<u32>;
@group(0) @binding(2) var<storage, read_write> tile_content: array<u32>;
// Per level, a u32 per square: 0 no object, the object's id where one object covers all of the
// square's masked pixels, MIXED_CELL where several do. Bound like the id maps.
@group(0) @binding(6) var<storage, read> cell_map_0: array<u32>;
@group(0) @binding(7) var<storage, read> cell_map_1: array<u32>;
@group(0) @binding(8) var<storage, read> cell_map_2: array<u32>;

fn cell_object(map: u32, cell: u32) -> u32 {
    switch map {
        case 1u: {
            return cell_map_1[cell];
        }
        case 2u: {
            return cell_map_2[cell];
        }
        default: {
            return cell_map_0[cell];
        }
    }
}

// Whether any pixel of square `cell` belongs to the slot's object.
fn cell_holds_object(cell: vec2<u32>) -> bool {
    let start = cell * SKIP_CELL;
    let end = min(start + SKIP_CELL, vec2<u32>(params.width, params.height));
    for (var y = start.y; y < end.y; y++) {
        for (var x = start.x; x < end.x; x++) {
            if in_slot_object(pixel_index(i32(x), i32(y))) {
                return true;
            }
        }
    }
    return false;
}

@compute @workgroup_size(64)
fn loss_cell_content(@builtin(global_invocation_id) id: vec3<u32>) {
    slot = id.y;
    let cells = cell_grid();
    let per_slot = cells.x * cells.y;
    if id.x >= per_slot {
        return;
    }
    let mask = params.slots[slot];
    let object = cell_object(mask.x, id.x);
    var content = occupancy[(params.first_rendered + slot) * per_slot + id.x] != 0u
        || object == mask.y;
    if !content && object == MIXED_CELL {
        content = cell_holds_object(vec2<u32>(id.x % cells.x, id.x / cells.x));
    }
    tile_content[slot * per_slot + id.x] = u32(content);
}
