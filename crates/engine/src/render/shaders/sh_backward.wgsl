// Backward of the SH colour, one invocation per Gaussian: d loss / d colour (zero on channels the
// forward clamped at 0) to SH coefficients, and through the view direction to the mean. ADDS into
// the gradient buffers. Runs after project_backward (both add to grad_means).

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> means: array<f32>;
@group(0) @binding(2) var<storage, read> sh_dc: array<f32>;
@group(0) @binding(3) var<storage, read> sh_rest0: array<f32>;
@group(0) @binding(4) var<storage, read> sh_rest1: array<f32>;
@group(0) @binding(5) var<storage, read> sh_rest2: array<f32>;
@group(0) @binding(6) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> grad_projected: array<f32>;
@group(0) @binding(8) var<storage, read_write> grad_means: array<f32>;
@group(0) @binding(9) var<storage, read_write> grad_sh_dc: array<f32>;
@group(0) @binding(10) var<storage, read_write> grad_sh_rest0: array<f32>;
@group(0) @binding(11) var<storage, read_write> grad_sh_rest1: array<f32>;
@group(0) @binding(12) var<storage, read_write> grad_sh_rest2: array<f32>;

const GROUP_SIZE: u32 = 256u;

fn add_sh_grad(i: u32, k: u32, v: vec3<f32>) {
    if k == 0u {
        grad_sh_dc[3u * i] += v.x;
        grad_sh_dc[3u * i + 1u] += v.y;
        grad_sh_dc[3u * i + 2u] += v.z;
        return;
    }
    let group = (k - 1u) / 5u;
    let base = i * 15u + ((k - 1u) % 5u) * 3u;
    if group == 0u {
        grad_sh_rest0[base] += v.x;
        grad_sh_rest0[base + 1u] += v.y;
        grad_sh_rest0[base + 2u] += v.z;
    } else if group == 1u {
        grad_sh_rest1[base] += v.x;
        grad_sh_rest1[base + 1u] += v.y;
        grad_sh_rest1[base + 2u] += v.z;
    } else {
        grad_sh_rest2[base] += v.x;
        grad_sh_rest2[base + 1u] += v.y;
        grad_sh_rest2[base + 2u] += v.z;
    }
}

// Coefficient k's backward: adds its gradient and answers its share of d loss / d direction.
fn sh_term_backward(i: u32, k: u32, direction: vec3<f32>, v_colour: vec3<f32>) -> vec3<f32> {
    add_sh_grad(i, k, sh_basis(k, direction) * v_colour);
    return sh_basis_gradient(k, direction) * dot(sh_coefficient(i, k), v_colour);
}

@compute @workgroup_size(256)
fn sh_backward(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let i = flat_index(gid, num_groups, GROUP_SIZE);
    if i >= uniforms.gaussian_count || projected[3u * i + 1u].w == 0.0 {
        return;
    }
    let g = i * GRAD_STRIDE;
    let mean = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let offset = mean - uniforms.camera_position.xyz;
    let distance = length(offset);
    let direction = offset / distance;
    let raw_colour = sh_colour(i, uniforms.sh_degree, direction);
    let v_colour = select(
        vec3<f32>(grad_projected[g + 5u], grad_projected[g + 6u], grad_projected[g + 7u]),
        vec3<f32>(0.0),
        raw_colour < vec3<f32>(0.0),
    );
    // Band by band with literal indices, as sh_colour (sh.wgsl) and for the same reason.
    let degree = uniforms.sh_degree;
    var v_direction = sh_term_backward(i, 0u, direction, v_colour);
    if degree >= 1u {
        v_direction += sh_term_backward(i, 1u, direction, v_colour);
        v_direction += sh_term_backward(i, 2u, direction, v_colour);
        v_direction += sh_term_backward(i, 3u, direction, v_colour);
    }
    if degree >= 2u {
        v_direction += sh_term_backward(i, 4u, direction, v_colour);
        v_direction += sh_term_backward(i, 5u, direction, v_colour);
        v_direction += sh_term_backward(i, 6u, direction, v_colour);
        v_direction += sh_term_backward(i, 7u, direction, v_colour);
        v_direction += sh_term_backward(i, 8u, direction, v_colour);
    }
    if degree >= 3u {
        v_direction += sh_term_backward(i, 9u, direction, v_colour);
        v_direction += sh_term_backward(i, 10u, direction, v_colour);
        v_direction += sh_term_backward(i, 11u, direction, v_colour);
        v_direction += sh_term_backward(i, 12u, direction, v_colour);
        v_direction += sh_term_backward(i, 13u, direction, v_colour);
        v_direction += sh_term_backward(i, 14u, direction, v_colour);
        v_direction += sh_term_backward(i, 15u, direction, v_colour);
    }
    let v_mean = (v_direction - direction * dot(direction, v_direction)) / distance;
    grad_means[3u * i] += v_mean.x;
    grad_means[3u * i + 1u] += v_mean.y;
    grad_means[3u * i + 2u] += v_mean.z;
}
