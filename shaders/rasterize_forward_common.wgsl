// What both rasterize forward kernels share (rasterize_forward.wgsl, one pixel per invocation;
// rasterize_forward_columns.wgsl, columns of pixels on software adapters): bindings, staging a
// batch of splats (rasterize_batch.wgsl) front to back, the tile's range, and the early-out vote.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(2) var<storage, read> intersection_gaussians: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> image: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> final_transmittance: array<f32>;
@group(0) @binding(6) var<storage, read_write> last_contributor: array<u32>;
@group(0) @binding(7) var<storage, read_write> depth: array<f32>;

var<workgroup> range_start: u32;
var<workgroup> range_end: u32;
// Invocations with a pixel still unsaturated, counted before each batch.
var<workgroup> active_invocations: atomic<u32>;
var<workgroup> active_snapshot: u32;

// Stages splat `slot` of the batch starting at intersection `first`.
fn stage_splat(first: u32, slot: u32) {
    stage_projected(slot, intersection_gaussians[first + slot]);
}

// The tile's [start, end) in the sorted intersections, the same in every invocation.
fn load_tile_range(tile: u32, local_index: u32) -> vec2<u32> {
    if local_index == 0u {
        range_start = tile_ranges[2u * tile];
        range_end = tile_ranges[2u * tile + 1u];
    }
    return vec2<u32>(workgroupUniformLoad(&range_start), workgroupUniformLoad(&range_end));
}

// Whether any invocation of the workgroup is `still_working` (called by all, between batches).
fn any_invocation_active(still_working: bool, local_index: u32) -> bool {
    if local_index == 0u {
        atomicStore(&active_invocations, 0u);
    }
    workgroupBarrier();
    if still_working {
        atomicAdd(&active_invocations, 1u);
    }
    workgroupBarrier();
    if local_index == 0u {
        active_snapshot = atomicLoad(&active_invocations);
    }
    return workgroupUniformLoad(&active_snapshot) != 0u;
}
