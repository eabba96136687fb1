// Folds one render's screen-space gradient statistic into the densification accumulators
// (per Gaussian): the norm of the absolute 2D mean gradient in NDC units (pixels x half image
// size, so thresholds match 3DGS / gsplat), how often the Gaussian was visible, and its largest
// projected radius as a fraction of the image's longer side.

struct StatsUniforms {
    gaussian_count: u32,
    half_width: f32,
    half_height: f32,
    longer_side: f32,
}

@group(0) @binding(0) var<uniform> uniforms: StatsUniforms;
// The renderer's projected splats: 3 vec4 per Gaussian; [3 i + 1].w is the radius (0 = culled).
@group(0) @binding(1) var<storage, read> projected: array<vec4<f32>>;
// Sum over pixels of |d loss / d mean2d| per axis, in pixels (2 per Gaussian).
@group(0) @binding(2) var<storage, read> mean2d_abs: array<f32>;
@group(0) @binding(3) var<storage, read_write> gradient_sums: array<f32>;
@group(0) @binding(4) var<storage, read_write> visible_counts: array<u32>;
@group(0) @binding(5) var<storage, read_write> max_radii: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let index = gid.x + gid.y * groups.x * 256u;
    if index >= uniforms.gaussian_count {
        return;
    }
    let radius = projected[3u * index + 1u].w;
    if radius <= 0.0 {
        return;
    }
    let ndc_gradient = vec2<f32>(
        mean2d_abs[2u * index] * uniforms.half_width,
        mean2d_abs[2u * index + 1u] * uniforms.half_height,
    );
    gradient_sums[index] += length(ndc_gradient);
    visible_counts[index] += 1u;
    max_radii[index] = max(max_radii[index], radius / uniforms.longer_side);
}
