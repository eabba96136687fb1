// Object losses only: whether each SKIP_CELL square of each slot holds content, i.e. any pixel
// whose rendered or (masked) target colour is non-zero. One workgroup per LOSS_TILE square and
// slot (z), CONTENT_TILES_PER_GROUP tiles side by side per workgroup. An object's render and
// mask usually cover a small part of the image, and where both are zero over the whole SSIM
// reach the loss and its gradient are exactly zero (loss_skip.wgsl). Losses whose renders
// marked their occupancy read that instead of every pixel (loss_cell_content.wgsl).

// Zeroed before the pass; a row with content marks its cells. No workgroup memory or barriers:
// a CPU adapter pays for a barrier in every workgroup.
@group(0) @binding(6) var<storage, read_write> tile_content: array<atomic<u32>>;

const CELLS_PER_TILE: u32 = LOSS_TILE / SKIP_CELL;

// One invocation per row of the tile, so a tile costs at most LOSS_TILE x CELLS_PER_TILE atomic
// stores (a CPU adapter issues atomics lane by lane), and a row stops scanning a cell at its
// first content pixel.
@compute @workgroup_size(LOSS_TILE * CONTENT_TILES_PER_GROUP)
fn loss_tile_content(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    slot = workgroup.z;
    let row = local % LOSS_TILE;
    let tile_x = workgroup.x * CONTENT_TILES_PER_GROUP + local / LOSS_TILE;
    let y = i32(workgroup.y * LOSS_TILE + row);
    if y >= i32(params.height) || tile_x >= params.tiles_x {
        return;
    }
    let cells = cell_grid();
    let cell_y = u32(y) / SKIP_CELL;
    for (var part = 0u; part < CELLS_PER_TILE; part++) {
        let cell_x = tile_x * CELLS_PER_TILE + part;
        let start = i32(cell_x * SKIP_CELL);
        let end = min(start + i32(SKIP_CELL), i32(params.width));
        for (var x = start; x < end; x++) {
            let pixel = pixel_index(x, y);
            if any(rendered_rgb(pixel) != vec3<f32>(0.0)) || any(target_rgb(pixel) != vec3<f32>(0.0)) {
                atomicStore(&tile_content[slot * cells.x * cells.y + cell_y * cells.x + cell_x], 1u);
                break;
            }
        }
    }
}
