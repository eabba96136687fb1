// What both rasterize backward kernels share (rasterize_backward.wgsl, one pixel per invocation;
// rasterize_backward_columns.wgsl, columns of pixels on software adapters): bindings, staging a
// batch of splats (rasterize_batch.wgsl) back to front, and the longest walk of the tile.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(2) var<storage, read> intersection_gaussians: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> final_transmittance: array<f32>;
@group(0) @binding(5) var<storage, read> last_contributor: array<u32>;
@group(0) @binding(6) var<storage, read> grad_image: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> grad_projected: array<AtomicF32>;

var<workgroup> batch_gaussian: array<u32, 256>;
var<workgroup> range_start: u32;
var<workgroup> longest: atomic<u32>;
var<workgroup> longest_snapshot: u32;

// The tile's first intersection and the most intersections any of its pixels walks (each
// invocation passes the most of its own pixels), the same in every invocation.
fn tile_walk(tile: u32, local_index: u32, contributed: u32) -> vec2<u32> {
    if local_index == 0u {
        range_start = tile_ranges[2u * tile];
        atomicStore(&longest, 0u);
    }
    workgroupBarrier();
    atomicMax(&longest, contributed);
    workgroupBarrier();
    if local_index == 0u {
        longest_snapshot = atomicLoad(&longest);
    }
    return vec2<u32>(workgroupUniformLoad(&range_start), workgroupUniformLoad(&longest_snapshot));
}

// Stages splat `slot` of a back-to-front batch whose last range position is `batch_end - 1`.
fn stage_splat_backwards(start: u32, batch_end: u32, slot: u32) {
    let gaussian = intersection_gaussians[start + batch_end - 1u - slot];
    batch_gaussian[slot] = gaussian;
    stage_projected(slot, gaussian);
}
