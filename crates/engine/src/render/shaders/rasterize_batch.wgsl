// The batch of splats a rasterize workgroup stages in workgroup memory, shared by the per-pixel
// forward and backward kernels (their rasterize_*_common.wgsl declares the `projected` binding
// read here). The column kernels read splats a subgroup lane each instead
// (rasterize_lane_chunk.wgsl).

const BATCH: u32 = 256u;

var<workgroup> batch_mean_opacity: array<vec4<f32>, 256>;
var<workgroup> batch_conic: array<vec4<f32>, 256>;
var<workgroup> batch_colour: array<vec4<f32>, 256>;

struct StagedSplat {
    mean_opacity: vec4<f32>,
    conic: vec3<f32>,
    colour: vec3<f32>,
}

// Copies Gaussian `gaussian`'s projected splat into batch slot `slot`.
fn stage_projected(slot: u32, gaussian: u32) {
    batch_mean_opacity[slot] = projected[3u * gaussian];
    batch_conic[slot] = projected[3u * gaussian + 1u];
    batch_colour[slot] = projected[3u * gaussian + 2u];
}

fn staged_splat(t: u32) -> StagedSplat {
    return StagedSplat(batch_mean_opacity[t], batch_conic[t].xyz, batch_colour[t].xyz);
}
