// Rasterisation: one 16x16 workgroup per tile, one invocation per pixel. The tile's splats (in
// depth order) are loaded in batches of 256 into workgroup memory and composited front to back;
// the workgroup stops when every pixel is saturated.
//
// Per pixel outputs: image (rgb with background, alpha), final transmittance, and the number of
// the tile's intersections processed up to the last one that contributed (backward starts there).

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(2) var<storage, read> intersection_gaussians: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> image: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> final_transmittance: array<f32>;
@group(0) @binding(6) var<storage, read_write> last_contributor: array<u32>;
@group(0) @binding(7) var<storage, read_write> depth: array<f32>;

const BATCH: u32 = 256u;

var<workgroup> batch_mean_opacity: array<vec4<f32>, 256>;
var<workgroup> batch_conic: array<vec4<f32>, 256>;
var<workgroup> batch_colour: array<vec4<f32>, 256>;
var<workgroup> range_start: u32;
var<workgroup> range_end: u32;
var<workgroup> active_pixels: atomic<u32>;
var<workgroup> active_snapshot: u32;

@compute @workgroup_size(16, 16)
fn rasterize_forward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tile = group.y * uniforms.tile_grid.x + group.x;
    let pixel = group.xy * TILE_SIZE + local.xy;
    let inside = pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y;
    let centre = vec2<f32>(pixel) + 0.5;
    if local_index == 0u {
        range_start = tile_ranges[2u * tile];
        range_end = tile_ranges[2u * tile + 1u];
    }
    let start = workgroupUniformLoad(&range_start);
    let end = workgroupUniformLoad(&range_end);
    let batches = (end - start + BATCH - 1u) / BATCH;

    var done = !inside;
    var transmittance = 1.0;
    var rgb = vec3<f32>(0.0);
    var depth_sum = 0.0;
    var contributed = 0u;
    for (var b = 0u; b < batches; b++) {
        if local_index == 0u {
            atomicStore(&active_pixels, 0u);
        }
        workgroupBarrier();
        if !done {
            atomicAdd(&active_pixels, 1u);
        }
        workgroupBarrier();
        if local_index == 0u {
            active_snapshot = atomicLoad(&active_pixels);
        }
        if workgroupUniformLoad(&active_snapshot) == 0u {
            break;
        }
        let load = start + b * BATCH + local_index;
        if load < end {
            let gaussian = intersection_gaussians[load];
            batch_mean_opacity[local_index] = projected[3u * gaussian];
            batch_conic[local_index] = projected[3u * gaussian + 1u];
            batch_colour[local_index] = projected[3u * gaussian + 2u];
        }
        workgroupBarrier();
        let batch_size = min(BATCH, end - start - b * BATCH);
        for (var t = 0u; t < batch_size; t++) {
            if done {
                break;
            }
            let mean_opacity = batch_mean_opacity[t];
            let conic = batch_conic[t].xyz;
            let d = mean_opacity.xy - centre;
            let sigma = 0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) + conic.y * d.x * d.y;
            if sigma < 0.0 {
                continue;
            }
            let alpha = min(ALPHA_MAX, mean_opacity.z * exp(-sigma));
            if alpha < ALPHA_MIN {
                continue;
            }
            let next = transmittance * (1.0 - alpha);
            if next <= TRANSMITTANCE_MIN {
                done = true;
                break;
            }
            let weight = alpha * transmittance;
            rgb += batch_colour[t].xyz * weight;
            depth_sum += mean_opacity.w * weight;
            transmittance = next;
            contributed = b * BATCH + t + 1u;
        }
        workgroupBarrier();
    }
    if inside {
        let index = pixel.y * uniforms.image_size.x + pixel.x;
        image[index] = vec4<f32>(rgb + transmittance * uniforms.background.xyz, 1.0 - transmittance);
        final_transmittance[index] = transmittance;
        last_contributor[index] = contributed;
        depth[index] = depth_sum;
    }
}
