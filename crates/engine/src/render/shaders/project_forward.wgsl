// Projection: one invocation per Gaussian. Writes the screen-space splat, its tile count (tiles
// its footprint touches, tile_footprint.wgsl) and its depth sort key; culled Gaussians (filtered
// out, outside near/far, degenerate, too transparent to show, touching no tile) get radius 0,
// tile count 0 and the largest key so they sort last.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> means: array<f32>;
@group(0) @binding(2) var<storage, read> log_scales: array<f32>;
@group(0) @binding(3) var<storage, read> rotations: array<f32>;
@group(0) @binding(4) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(5) var<storage, read> sh_dc: array<f32>;
@group(0) @binding(6) var<storage, read> sh_rest0: array<f32>;
@group(0) @binding(7) var<storage, read> sh_rest1: array<f32>;
@group(0) @binding(8) var<storage, read> sh_rest2: array<f32>;
@group(0) @binding(9) var<storage, read> object_ids: array<u32>;
@group(0) @binding(10) var<storage, read_write> projected: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read_write> tile_counts: array<u32>;
@group(0) @binding(12) var<storage, read_write> depth_keys: array<u32>;
@group(0) @binding(13) var<storage, read_write> depth_values: array<u32>;

const GROUP_SIZE: u32 = 256u;

fn cull(i: u32) {
    projected[3u * i] = vec4<f32>(0.0);
    projected[3u * i + 1u] = vec4<f32>(0.0);
    projected[3u * i + 2u] = vec4<f32>(0.0);
    tile_counts[i] = 0u;
    depth_keys[i] = CULLED_KEY;
    depth_values[i] = i;
}

@compute @workgroup_size(256)
fn project_forward(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let i = flat_index(gid, num_groups, GROUP_SIZE);
    if i >= uniforms.gaussian_count {
        return;
    }
    if uniforms.filter_enabled != 0u && object_ids[3u * i + uniforms.filter_level] != uniforms.filter_id {
        cull(i);
        return;
    }
    let mean = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let w = camera_rotation(uniforms);
    let p = w * mean + uniforms.camera_from_world[3].xyz;
    if p.z <= uniforms.near || p.z >= uniforms.far {
        cull(i);
        return;
    }
    let q = vec4<f32>(rotations[4u * i], rotations[4u * i + 1u], rotations[4u * i + 2u], rotations[4u * i + 3u]);
    let r = rotation_from_quaternion(normalize(q));
    let s = exp(vec3<f32>(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]));
    let m = mat3x3<f32>(r[0] * s.x, r[1] * s.y, r[2] * s.z);
    let covariance_camera = w * (m * transpose(m)) * transpose(w);
    let j = perspective_jacobian(uniforms, p);
    // cov2d = J Sc J^T
    let sc_j0 = covariance_camera * j.row0;
    let sc_j1 = covariance_camera * j.row1;
    let a = dot(j.row0, sc_j0) + COVARIANCE_DILATION;
    let b = dot(j.row0, sc_j1);
    let c = dot(j.row1, sc_j1) + COVARIANCE_DILATION;
    let det = a * c - b * b;
    if !(det > 0.0) {
        cull(i);
        return;
    }
    let conic = vec3<f32>(c / det, -b / det, a / det);
    let opacity = 1.0 / (1.0 + exp(-opacity_logits[i]));
    let sigma_max = footprint_sigma(opacity);
    if !(sigma_max > 0.0) {
        cull(i);
        return;
    }
    let mean2d = uniforms.focal * p.xy / p.z + uniforms.principal;
    let footprint = splat_footprint(mean2d, conic, sigma_max);
    let rows = footprint_tile_rows(footprint, uniforms.tile_grid);
    var tiles = 0u;
    for (var row = rows.x; row < rows.y; row++) {
        let columns = footprint_tile_columns(footprint, row, uniforms.tile_grid.x);
        tiles += columns.y - min(columns.x, columns.y);
    }
    if tiles == 0u {
        cull(i);
        return;
    }
    // 3DGS's screen radius, which densification's size statistics read.
    let mid = 0.5 * (a + c);
    let lambda = mid + sqrt(max(0.1, mid * mid - det));
    let radius = ceil(RADIUS_SIGMAS * sqrt(lambda));
    let direction = normalize(mean - uniforms.camera_position.xyz);
    let colour = max(sh_colour(i, uniforms.sh_degree, direction), vec3<f32>(0.0));
    projected[3u * i] = vec4<f32>(mean2d, opacity, p.z);
    projected[3u * i + 1u] = vec4<f32>(conic, radius);
    projected[3u * i + 2u] = vec4<f32>(colour, 0.0);
    tile_counts[i] = tiles;
    depth_keys[i] = bitcast<u32>(p.z);
    depth_values[i] = i;
}
