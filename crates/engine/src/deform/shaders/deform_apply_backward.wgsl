// Backward of the deformation (see deform_apply_common.wgsl). The rasteriser left d loss / d
// deformed geometry in the gradient buffers; this writes d loss / d head outputs for the MLP and
// turns the mean and rotation gradients into d loss / d canonical in place (the log-scale
// gradient passes through unchanged).

@group(0) @binding(4) var<storage, read_write> grad_means: array<f32>;
@group(0) @binding(5) var<storage, read_write> grad_rotations: array<f32>;
@group(0) @binding(6) var<storage, read> grad_log_scales: array<f32>;
@group(0) @binding(7) var<storage, read_write> grad_head: array<f32>;

@compute @workgroup_size(256, 1, 1)
fn deform_apply_backward(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let n = gaussian_index(group, groups, thread);
    if n >= params.count {
        return;
    }
    let g = params.first + n;
    let row = n * params.head_stride;
    let grad_moved = vec3<f32>(grad_means[3u * g], grad_means[3u * g + 1u], grad_means[3u * g + 2u]);
    var at = 3u;
    if params.screw != 0u {
        let w = head_vec3(row, 0u);
        let v = head_vec3(row, 3u);
        let x = canonical_mean(g);
        let t2 = dot(w, w);
        let k = screw_coefficients(t2);
        let gw = dot(grad_moved, w);
        let gx = dot(grad_moved, x);
        let gv = dot(grad_moved, v);
        let wx = dot(w, x);
        let wv = dot(w, v);
        let x_cross_g = cross(x, grad_moved);
        let v_cross_g = cross(v, grad_moved);
        var grad_w = k.a * x_cross_g
            + k.b * (x * gw + grad_moved * wx - 2.0 * w * gx)
            + k.b * v_cross_g
            + k.c * (v * gw + grad_moved * wv - 2.0 * w * gv);
        let radial = k.da_over_t * dot(w, x_cross_g)
            + k.db_over_t * (wx * gw - t2 * gx)
            + k.db_over_t * dot(w, v_cross_g)
            + k.dc_over_t * (wv * gw - t2 * gv);
        grad_w += radial * w;
        // R^T = R(-w) and V^T = V(-w).
        let minus_w = -w;
        let wg = cross(minus_w, grad_moved);
        let grad_x = grad_moved + k.a * wg + k.b * cross(minus_w, wg);
        let grad_v = grad_moved + k.b * wg + k.c * cross(minus_w, wg);
        for (var i = 0u; i < 3u; i++) {
            grad_head[row + i] = grad_w[i];
            grad_head[row + 3u + i] = grad_v[i];
            grad_means[3u * g + i] = grad_x[i];
        }
        at = 6u;
    } else {
        for (var i = 0u; i < 3u; i++) {
            grad_head[row + i] = grad_moved[i];
        }
    }
    let q = canonical_rotation(g);
    let norm = max(length(q), 1.0e-12);
    let unit = q / norm;
    let grad_q = vec4<f32>(
        grad_rotations[4u * g],
        grad_rotations[4u * g + 1u],
        grad_rotations[4u * g + 2u],
        grad_rotations[4u * g + 3u],
    );
    let grad_canonical_q = (grad_q - unit * dot(unit, grad_q)) / norm;
    for (var i = 0u; i < 4u; i++) {
        grad_head[row + at + i] = grad_q[i];
        grad_rotations[4u * g + i] = grad_canonical_q[i];
    }
    for (var i = 0u; i < 3u; i++) {
        grad_head[row + at + 4u + i] = grad_log_scales[3u * g + i];
    }
}
