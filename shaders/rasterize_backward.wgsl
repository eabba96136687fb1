// Backward of rasterize_forward: one 16x16 workgroup per tile; each pixel walks its splats back to
// front from its last contributor, recovering the transmittance before each fragment by division
// (as 3DGS/gsplat do), and adds d loss / d (mean2d, conic, colour, opacity) and |d loss / d mean2d|
// into grad_projected with float atomics (native or CAS: rasterize_grad_atomics_*.wgsl), summed
// over the subgroup first on hardware with subgroups (rasterize_grad_emit_*.wgsl). The loop
// over a batch's splats stays uniform (no early `continue`) so the subgroup sums are legal.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(2) var<storage, read> intersection_gaussians: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> final_transmittance: array<f32>;
@group(0) @binding(5) var<storage, read> last_contributor: array<u32>;
@group(0) @binding(6) var<storage, read> grad_image: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> grad_projected: array<AtomicF32>;

const BATCH: u32 = 256u;

var<workgroup> batch_gaussian: array<u32, 256>;
var<workgroup> batch_mean_opacity: array<vec4<f32>, 256>;
var<workgroup> batch_conic: array<vec4<f32>, 256>;
var<workgroup> batch_colour: array<vec4<f32>, 256>;
var<workgroup> range_start: u32;
var<workgroup> longest: atomic<u32>;
var<workgroup> longest_snapshot: u32;

@compute @workgroup_size(16, 16)
fn rasterize_backward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tile = group.y * uniforms.tile_grid.x + group.x;
    let pixel = group.xy * TILE_SIZE + local.xy;
    let inside = pixel.x < uniforms.image_size.x && pixel.y < uniforms.image_size.y;
    let centre = vec2<f32>(pixel) + 0.5;
    let pixel_index = pixel.y * uniforms.image_size.x + pixel.x;

    var t_final = 1.0;
    var contributed = 0u;
    var v_out = vec4<f32>(0.0);
    if inside {
        t_final = final_transmittance[pixel_index];
        contributed = last_contributor[pixel_index];
        v_out = grad_image[pixel_index];
    }
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
    let start = workgroupUniformLoad(&range_start);
    let count = workgroupUniformLoad(&longest_snapshot);
    let batches = (count + BATCH - 1u) / BATCH;
    let background_term = dot(uniforms.background.xyz, v_out.xyz);

    var transmittance = t_final;
    var behind = vec3<f32>(0.0);
    for (var b = 0u; b < batches; b++) {
        // Batch b holds range positions [count - (b + 1) * BATCH, count - b * BATCH), back to front.
        let batch_end = count - b * BATCH;
        let batch_size = min(BATCH, batch_end);
        if local_index < batch_size {
            let gaussian = intersection_gaussians[start + batch_end - 1u - local_index];
            batch_gaussian[local_index] = gaussian;
            batch_mean_opacity[local_index] = projected[3u * gaussian];
            batch_conic[local_index] = projected[3u * gaussian + 1u];
            batch_colour[local_index] = projected[3u * gaussian + 2u];
        }
        workgroupBarrier();
        for (var t = 0u; t < batch_size; t++) {
            let position = batch_end - 1u - t;
            let mean_opacity = batch_mean_opacity[t];
            let conic = batch_conic[t].xyz;
            let d = mean_opacity.xy - centre;
            let sigma = 0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) + conic.y * d.x * d.y;
            let value = exp(-max(sigma, 0.0));
            let alpha = min(ALPHA_MAX, mean_opacity.z * value);
            let contributes = position < contributed && sigma >= 0.0 && alpha >= ALPHA_MIN;
            var grads = FragmentGrads(vec2<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, vec2<f32>(0.0));
            if contributes {
                let one_over_rest = 1.0 / (1.0 - alpha);
                transmittance *= one_over_rest;
                let weight = alpha * transmittance;
                let colour = batch_colour[t].xyz;
                var v_alpha = dot(colour * transmittance - behind * one_over_rest, v_out.xyz);
                v_alpha += t_final * one_over_rest * (v_out.w - background_term);
                grads.colour = weight * v_out.xyz;
                if mean_opacity.z * value <= ALPHA_MAX {
                    let v_sigma = -mean_opacity.z * value * v_alpha;
                    let v_mean = v_sigma * vec2<f32>(conic.x * d.x + conic.y * d.y, conic.y * d.x + conic.z * d.y);
                    grads.mean = v_mean;
                    grads.conic = vec3<f32>(0.5 * v_sigma * d.x * d.x, v_sigma * d.x * d.y, 0.5 * v_sigma * d.y * d.y);
                    grads.opacity = value * v_alpha;
                    grads.mean_abs = abs(v_mean);
                }
                behind += colour * weight;
            }
            emit_fragment_grads(batch_gaussian[t], grads, contributes);
        }
        workgroupBarrier();
    }
}
