// The bindings both rasterize forward kernels share (rasterize_forward.wgsl, one pixel per
// invocation; rasterize_forward_columns.wgsl, columns of pixels on software adapters).

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(2) var<storage, read> intersection_gaussians: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> image: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> final_transmittance: array<f32>;
@group(0) @binding(6) var<storage, read_write> last_contributor: array<u32>;
@group(0) @binding(7) var<storage, read_write> depth: array<f32>;
// Per image (slot) and OCCUPANCY_CELL square, row-major over ceil(size / OCCUPANCY_CELL): 1 where
// some pixel's colour is non-zero. Written only with uniforms.mark_occupancy, over zeros.
@group(0) @binding(8) var<storage, read_write> occupancy: array<atomic<u32>>;

// Marks the square of `pixel` in image `slot` occupied.
fn mark_occupied(slot: u32, pixel: vec2<u32>) {
    let cells = (uniforms.image_size + OCCUPANCY_CELL - 1u) / OCCUPANCY_CELL;
    let cell = pixel / OCCUPANCY_CELL;
    atomicStore(&occupancy[(slot * cells.y + cell.y) * cells.x + cell.x], 1u);
}
