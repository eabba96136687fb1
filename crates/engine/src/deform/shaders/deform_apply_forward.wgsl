// Forward of the deformation (see deform_apply_common.wgsl): writes the deformed geometry the
// rasteriser reads; opacity, colour and object ids stay the canonical ones.

@group(0) @binding(4) var<storage, read> canonical_log_scales: array<f32>;
@group(0) @binding(5) var<storage, read_write> deformed_means: array<f32>;
@group(0) @binding(6) var<storage, read_write> deformed_log_scales: array<f32>;
@group(0) @binding(7) var<storage, read_write> deformed_rotations: array<f32>;

@compute @workgroup_size(256, 1, 1)
fn deform_apply_forward(
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
    let x = canonical_mean(g);
    var moved: vec3<f32>;
    var at = 3u;
    if params.screw != 0u {
        let w = head_vec3(row, 0u);
        let v = head_vec3(row, 3u);
        let k = screw_coefficients(dot(w, w));
        let wx = cross(w, x);
        let wv = cross(w, v);
        moved = x + k.a * wx + k.b * cross(w, wx) + v + k.b * wv + k.c * cross(w, wv);
        at = 6u;
    } else {
        moved = x + head_vec3(row, 0u);
    }
    deformed_means[3u * g] = moved.x;
    deformed_means[3u * g + 1u] = moved.y;
    deformed_means[3u * g + 2u] = moved.z;
    let q = canonical_rotation(g);
    let unit = q / max(length(q), 1.0e-12);
    for (var i = 0u; i < 4u; i++) {
        deformed_rotations[4u * g + i] = unit[i] + head[row + at + i];
    }
    for (var i = 0u; i < 3u; i++) {
        deformed_log_scales[3u * g + i] = canonical_log_scales[3u * g + i] + head[row + at + 4u + i];
    }
}
