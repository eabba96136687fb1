// Backward of the projection geometry, one invocation per Gaussian: maps d loss / d (mean2d,
// conic, opacity) to means, log-scales, rotations and opacity logits, and the |d mean2d| sum to
// the densification statistic. ADDS into the gradient buffers (several renders per step
// accumulate). Colour / SH gradients are sh_backward's.

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> means: array<f32>;
@group(0) @binding(2) var<storage, read> log_scales: array<f32>;
@group(0) @binding(3) var<storage, read> rotations: array<f32>;
@group(0) @binding(4) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> grad_projected: array<f32>;
@group(0) @binding(6) var<storage, read_write> grad_means: array<f32>;
@group(0) @binding(7) var<storage, read_write> grad_log_scales: array<f32>;
@group(0) @binding(8) var<storage, read_write> grad_rotations: array<f32>;
@group(0) @binding(9) var<storage, read_write> grad_opacity_logits: array<f32>;
@group(0) @binding(10) var<storage, read_write> grad_mean2d_abs: array<f32>;

const GROUP_SIZE: u32 = 256u;

fn outer(a: vec3<f32>, b: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(a * b.x, a * b.y, a * b.z);
}

@compute @workgroup_size(256)
fn project_backward(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) num_groups: vec3<u32>,
) {
    let i = flat_index(gid, num_groups, GROUP_SIZE);
    if i >= uniforms.gaussian_count || projected[3u * i + 1u].w == 0.0 {
        return;
    }
    let g = i * GRAD_STRIDE;
    let v_mean2d = vec2<f32>(grad_projected[g], grad_projected[g + 1u]);
    let v_conic = vec3<f32>(grad_projected[g + 2u], grad_projected[g + 3u], grad_projected[g + 4u]);
    let v_opacity = grad_projected[g + 8u];

    // Recompute the forward geometry.
    let mean = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let w = camera_rotation(uniforms);
    let p = w * mean + uniforms.camera_from_world[3].xyz;
    let q_raw = vec4<f32>(rotations[4u * i], rotations[4u * i + 1u], rotations[4u * i + 2u], rotations[4u * i + 3u]);
    let q_norm = length(q_raw);
    let q = q_raw / q_norm;
    let r = rotation_from_quaternion(q);
    let s = exp(vec3<f32>(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]));
    let m = mat3x3<f32>(r[0] * s.x, r[1] * s.y, r[2] * s.z);
    let sc = w * (m * transpose(m)) * transpose(w);
    let j = perspective_jacobian(uniforms, p);
    let sc_j0 = sc * j.row0;
    let sc_j1 = sc * j.row1;
    let a = dot(j.row0, sc_j0) + COVARIANCE_DILATION;
    let b = dot(j.row0, sc_j1);
    let c = dot(j.row1, sc_j1) + COVARIANCE_DILATION;
    let det = a * c - b * b;
    let conic = mat2x2<f32>(vec2<f32>(c / det, -b / det), vec2<f32>(-b / det, a / det));

    // Conic -> 2D covariance.
    let v_conic_matrix = mat2x2<f32>(vec2<f32>(v_conic.x, 0.5 * v_conic.y), vec2<f32>(0.5 * v_conic.y, v_conic.z));
    let v_cov = (conic * v_conic_matrix * conic) * -1.0;
    let v00 = v_cov[0][0];
    let v01 = v_cov[1][0];
    let v11 = v_cov[1][1];
    // cov2d = J Sc J^T.
    let v_sc = v00 * outer(j.row0, j.row0) + v01 * (outer(j.row0, j.row1) + outer(j.row1, j.row0))
        + v11 * outer(j.row1, j.row1);
    let v_j0 = 2.0 * (v00 * sc_j0 + v01 * sc_j1);
    let v_j1 = 2.0 * (v01 * sc_j0 + v11 * sc_j1);

    // Camera-space mean, from mean2d and from the Jacobian.
    let fx = uniforms.focal.x;
    let fy = uniforms.focal.y;
    let z = p.z;
    let z2 = z * z;
    var v_p = vec3<f32>(
        v_mean2d.x * fx / z,
        v_mean2d.y * fy / z,
        -(v_mean2d.x * fx * p.x + v_mean2d.y * fy * p.y) / z2,
    );
    v_p.z += -fx / z2 * v_j0.x - fy / z2 * v_j1.y;
    if j.clamped_x {
        v_p.z += fx * j.tan_clamped.x / z2 * v_j0.z;
    } else {
        v_p.x += -fx / z2 * v_j0.z;
        v_p.z += 2.0 * fx * p.x / (z2 * z) * v_j0.z;
    }
    if j.clamped_y {
        v_p.z += fy * j.tan_clamped.y / z2 * v_j1.z;
    } else {
        v_p.y += -fy / z2 * v_j1.z;
        v_p.z += 2.0 * fy * p.y / (z2 * z) * v_j1.z;
    }
    let v_mean = transpose(w) * v_p;
    grad_means[3u * i] += v_mean.x;
    grad_means[3u * i + 1u] += v_mean.y;
    grad_means[3u * i + 2u] += v_mean.z;

    // Covariance -> M = R S -> log-scales and quaternion.
    let v_sigma = transpose(w) * v_sc * w;
    let v_m = 2.0 * v_sigma * m;
    let v_r = mat3x3<f32>(v_m[0] * s.x, v_m[1] * s.y, v_m[2] * s.z);
    grad_log_scales[3u * i] += dot(r[0], v_m[0]) * s.x;
    grad_log_scales[3u * i + 1u] += dot(r[1], v_m[1]) * s.y;
    grad_log_scales[3u * i + 2u] += dot(r[2], v_m[2]) * s.z;
    // e(row, col) = v_r[col][row].
    let qw = q.x;
    let qx = q.y;
    let qy = q.z;
    let qz = q.w;
    let v_unit = 2.0 * vec4<f32>(
        -qz * v_r[1][0] + qy * v_r[2][0] + qz * v_r[0][1] - qx * v_r[2][1] - qy * v_r[0][2] + qx * v_r[1][2],
        qy * v_r[1][0] + qz * v_r[2][0] + qy * v_r[0][1] - 2.0 * qx * v_r[1][1] - qw * v_r[2][1]
            + qz * v_r[0][2] + qw * v_r[1][2] - 2.0 * qx * v_r[2][2],
        -2.0 * qy * v_r[0][0] + qx * v_r[1][0] + qw * v_r[2][0] + qx * v_r[0][1] + qz * v_r[2][1]
            - qw * v_r[0][2] + qz * v_r[1][2] - 2.0 * qy * v_r[2][2],
        -2.0 * qz * v_r[0][0] - qw * v_r[1][0] + qx * v_r[2][0] + qw * v_r[0][1] - 2.0 * qz * v_r[1][1]
            + qy * v_r[2][1] + qx * v_r[0][2] + qy * v_r[1][2],
    );
    let v_q = (v_unit - q * dot(q, v_unit)) / q_norm;
    grad_rotations[4u * i] += v_q.x;
    grad_rotations[4u * i + 1u] += v_q.y;
    grad_rotations[4u * i + 2u] += v_q.z;
    grad_rotations[4u * i + 3u] += v_q.w;

    let opacity = projected[3u * i].z;
    grad_opacity_logits[i] += v_opacity * opacity * (1.0 - opacity);
    grad_mean2d_abs[2u * i] += grad_projected[g + 9u];
    grad_mean2d_abs[2u * i + 1u] += grad_projected[g + 10u];
}
