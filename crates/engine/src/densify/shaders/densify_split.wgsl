// Split children: each is moved from its parent by a normal draw scaled by the parent's scales
// and rotated by its rotation, and shrunk by 1 / (0.8 * children) (3DGS). The draw is
// `split_draw::split_normal` in Rust (same hash, same Box-Muller); change both together.

@group(0) @binding(0) var<uniform> rules: Rules;
@group(0) @binding(1) var<storage, read> origin_source: array<u32>;
@group(0) @binding(2) var<storage, read> origin_kind: array<u32>;
@group(0) @binding(3) var<storage, read> old_means: array<f32>;
@group(0) @binding(4) var<storage, read> old_log_scales: array<f32>;
@group(0) @binding(5) var<storage, read> old_rotations: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> new_means: array<f32>;
@group(0) @binding(7) var<storage, read_write> new_log_scales: array<f32>;

fn hash32(value: u32) -> u32 {
    var x = value;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}

fn unit(bits: u32) -> f32 {
    return (f32(bits >> 8u) + 0.5) * (1.0 / 16777216.0);
}

fn split_normal(seed: u32, parent: u32, child: u32) -> vec3<f32> {
    let key = hash32(hash32(hash32(seed) ^ parent) ^ child);
    let u0 = unit(hash32(key));
    let u1 = unit(hash32(key + 1u));
    let u2 = unit(hash32(key + 2u));
    let u3 = unit(hash32(key + 3u));
    let tau = 6.283185307179586;
    let radius_a = sqrt(-2.0 * log(u0));
    let radius_b = sqrt(-2.0 * log(u2));
    return vec3<f32>(radius_a * cos(tau * u1), radius_a * sin(tau * u1), radius_b * cos(tau * u3));
}

// Rotates `v` by the unit quaternion (w, x, y, z) as glam's Quat * Vec3 does.
fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let w = q.x;
    let b = q.yzw;
    return v * (w * w - dot(b, b)) + b * (dot(v, b) * 2.0) + cross(b, v) * (w * 2.0);
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let row = flat_index(gid, groups);
    if row >= rules.new_count {
        return;
    }
    let kind = origin_kind[row];
    if kind < 2u {
        return;
    }
    let parent = origin_source[row];
    let log_scale = vec3<f32>(
        old_log_scales[3u * parent],
        old_log_scales[3u * parent + 1u],
        old_log_scales[3u * parent + 2u],
    );
    let sample = split_normal(rules.seed, parent, kind - 2u) * exp(log_scale);
    let offset = rotate(normalize(old_rotations[parent]), sample);
    for (var axis = 0u; axis < 3u; axis++) {
        new_means[3u * row + axis] = old_means[3u * parent + axis] + offset[axis];
        new_log_scales[3u * row + axis] = log_scale[axis] - rules.log_shrink;
    }
}
