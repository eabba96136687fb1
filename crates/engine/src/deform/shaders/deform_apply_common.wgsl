// Moves canonical Gaussians by the deformation field's head outputs, and the chain rule back.
// Same formulas as src/splat/deform/warp.rs (the f64 reference):
//   position: x + dx, or the screw motion exp([w, v]) x = R(w) x + V(w) v (screw = 1)
//   rotation: normalize(q) + dq        scale: log_s + ds (log space: every delta is a valid scale)
// Head row layout: [dx | w, v] then dq (4) then ds (3).

const SMALL_ANGLE: f32 = 1.0e-2;

struct ApplyParams {
    count: u32,
    first: u32,
    head_stride: u32,
    screw: u32,
}

@group(0) @binding(0) var<uniform> params: ApplyParams;
@group(0) @binding(1) var<storage, read> head: array<f32>;
@group(0) @binding(2) var<storage, read> canonical_means: array<f32>;
@group(0) @binding(3) var<storage, read> canonical_rotations: array<f32>;

struct ScrewCoefficients {
    a: f32,
    b: f32,
    c: f32,
    da_over_t: f32,
    db_over_t: f32,
    dc_over_t: f32,
}

// sin t / t, (1 - cos t) / t^2, (t - sin t) / t^3 and their derivatives over t (series near 0).
fn screw_coefficients(t2: f32) -> ScrewCoefficients {
    let theta = sqrt(t2);
    if theta < SMALL_ANGLE {
        return ScrewCoefficients(
            1.0 - t2 / 6.0 + t2 * t2 / 120.0,
            0.5 - t2 / 24.0 + t2 * t2 / 720.0,
            1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0,
            -1.0 / 3.0 + t2 / 30.0,
            -1.0 / 12.0 + t2 / 180.0,
            -1.0 / 60.0 + t2 / 1260.0,
        );
    }
    let s = sin(theta);
    let co = cos(theta);
    let t3 = t2 * theta;
    let t4 = t2 * t2;
    let t5 = t4 * theta;
    return ScrewCoefficients(
        s / theta,
        (1.0 - co) / t2,
        (theta - s) / t3,
        (theta * co - s) / t3,
        (theta * s - 2.0 * (1.0 - co)) / t4,
        (1.0 - co) / t4 - 3.0 * (theta - s) / t5,
    );
}

fn head_vec3(row: u32, at: u32) -> vec3<f32> {
    return vec3<f32>(head[row + at], head[row + at + 1u], head[row + at + 2u]);
}

fn canonical_mean(g: u32) -> vec3<f32> {
    return vec3<f32>(canonical_means[3u * g], canonical_means[3u * g + 1u], canonical_means[3u * g + 2u]);
}

fn canonical_rotation(g: u32) -> vec4<f32> {
    return vec4<f32>(
        canonical_rotations[4u * g],
        canonical_rotations[4u * g + 1u],
        canonical_rotations[4u * g + 2u],
        canonical_rotations[4u * g + 3u],
    );
}

fn gaussian_index(group: vec3<u32>, groups: vec3<u32>, thread: u32) -> u32 {
    return (group.x + group.y * groups.x) * 256u + thread;
}
