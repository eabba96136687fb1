// Real spherical harmonics up to degree 3 (3DGS constants and sign convention).
// Kernels that include this declare the storage arrays `sh_dc` (3 f32 per Gaussian) and
// `sh_rest0..2` (15 f32 per Gaussian: coefficients 1+5g ..= 5+5g, RGB each).

const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;
const SH_C2_0: f32 = 1.0925484305920792;
const SH_C2_1: f32 = -1.0925484305920792;
const SH_C2_2: f32 = 0.31539156525252005;
const SH_C2_3: f32 = -1.0925484305920792;
const SH_C2_4: f32 = 0.5462742152960396;
const SH_C3_0: f32 = -0.5900435899266435;
const SH_C3_1: f32 = 2.890611442640554;
const SH_C3_2: f32 = -0.4570457994644658;
const SH_C3_3: f32 = 0.3731763325901154;
const SH_C3_4: f32 = -0.4570457994644658;
const SH_C3_5: f32 = 1.445305721320277;
const SH_C3_6: f32 = -0.5900435899266435;

// Coefficient k (RGB) of Gaussian i.
fn sh_coefficient(i: u32, k: u32) -> vec3<f32> {
    if k == 0u {
        return vec3<f32>(sh_dc[3u * i], sh_dc[3u * i + 1u], sh_dc[3u * i + 2u]);
    }
    let group = (k - 1u) / 5u;
    let base = i * 15u + ((k - 1u) % 5u) * 3u;
    if group == 0u {
        return vec3<f32>(sh_rest0[base], sh_rest0[base + 1u], sh_rest0[base + 2u]);
    } else if group == 1u {
        return vec3<f32>(sh_rest1[base], sh_rest1[base + 1u], sh_rest1[base + 2u]);
    }
    return vec3<f32>(sh_rest2[base], sh_rest2[base + 1u], sh_rest2[base + 2u]);
}

fn sh_basis(k: u32, d: vec3<f32>) -> f32 {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    let xx = x * x;
    let yy = y * y;
    let zz = z * z;
    switch k {
        case 0u: { return SH_C0; }
        case 1u: { return -SH_C1 * y; }
        case 2u: { return SH_C1 * z; }
        case 3u: { return -SH_C1 * x; }
        case 4u: { return SH_C2_0 * x * y; }
        case 5u: { return SH_C2_1 * y * z; }
        case 6u: { return SH_C2_2 * (2.0 * zz - xx - yy); }
        case 7u: { return SH_C2_3 * x * z; }
        case 8u: { return SH_C2_4 * (xx - yy); }
        case 9u: { return SH_C3_0 * y * (3.0 * xx - yy); }
        case 10u: { return SH_C3_1 * x * y * z; }
        case 11u: { return SH_C3_2 * y * (4.0 * zz - xx - yy); }
        case 12u: { return SH_C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy); }
        case 13u: { return SH_C3_4 * x * (4.0 * zz - xx - yy); }
        case 14u: { return SH_C3_5 * z * (xx - yy); }
        default: { return SH_C3_6 * x * (xx - 3.0 * yy); }
    }
}

// d basis_k / d (x, y, z), components treated as independent.
fn sh_basis_gradient(k: u32, d: vec3<f32>) -> vec3<f32> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    let xx = x * x;
    let yy = y * y;
    let zz = z * z;
    switch k {
        case 0u: { return vec3<f32>(0.0); }
        case 1u: { return vec3<f32>(0.0, -SH_C1, 0.0); }
        case 2u: { return vec3<f32>(0.0, 0.0, SH_C1); }
        case 3u: { return vec3<f32>(-SH_C1, 0.0, 0.0); }
        case 4u: { return vec3<f32>(SH_C2_0 * y, SH_C2_0 * x, 0.0); }
        case 5u: { return vec3<f32>(0.0, SH_C2_1 * z, SH_C2_1 * y); }
        case 6u: { return vec3<f32>(-2.0 * SH_C2_2 * x, -2.0 * SH_C2_2 * y, 4.0 * SH_C2_2 * z); }
        case 7u: { return vec3<f32>(SH_C2_3 * z, 0.0, SH_C2_3 * x); }
        case 8u: { return vec3<f32>(2.0 * SH_C2_4 * x, -2.0 * SH_C2_4 * y, 0.0); }
        case 9u: { return vec3<f32>(6.0 * SH_C3_0 * x * y, SH_C3_0 * (3.0 * xx - 3.0 * yy), 0.0); }
        case 10u: { return vec3<f32>(SH_C3_1 * y * z, SH_C3_1 * x * z, SH_C3_1 * x * y); }
        case 11u: {
            return vec3<f32>(-2.0 * SH_C3_2 * x * y, SH_C3_2 * (4.0 * zz - xx - 3.0 * yy), 8.0 * SH_C3_2 * y * z);
        }
        case 12u: {
            return vec3<f32>(-6.0 * SH_C3_3 * x * z, -6.0 * SH_C3_3 * y * z, SH_C3_3 * (6.0 * zz - 3.0 * xx - 3.0 * yy));
        }
        case 13u: {
            return vec3<f32>(SH_C3_4 * (4.0 * zz - 3.0 * xx - yy), -2.0 * SH_C3_4 * x * y, 8.0 * SH_C3_4 * x * z);
        }
        case 14u: { return vec3<f32>(2.0 * SH_C3_5 * x * z, -2.0 * SH_C3_5 * y * z, SH_C3_5 * (xx - yy)); }
        default: { return vec3<f32>(SH_C3_6 * (3.0 * xx - 3.0 * yy), -6.0 * SH_C3_6 * x * y, 0.0); }
    }
}

// Coefficient k's share of the colour along unit direction d.
fn sh_term(i: u32, k: u32, d: vec3<f32>) -> vec3<f32> {
    return sh_basis(k, d) * sh_coefficient(i, k);
}

// Unclamped colour (SH + 0.5) of Gaussian i seen along unit direction d. Written out band by band
// with literal coefficient indices rather than as a loop over the coefficients: the compiler then
// folds sh_basis's switch and sh_coefficient's choice of buffer away, where a software adapter
// ran every case and every buffer's load under a mask for each coefficient (lavapipe, figurine
// at 256 px, 200 steps, best of 3 alternated runs: project_forward 2.84 -> 2.38 ms a step,
// sh_backward 1.27 -> 0.55). The sum runs in the same order as the loop did.
fn sh_colour(i: u32, degree: u32, d: vec3<f32>) -> vec3<f32> {
    var colour = vec3<f32>(0.5);
    colour += sh_term(i, 0u, d);
    if degree >= 1u {
        colour += sh_term(i, 1u, d);
        colour += sh_term(i, 2u, d);
        colour += sh_term(i, 3u, d);
    }
    if degree >= 2u {
        colour += sh_term(i, 4u, d);
        colour += sh_term(i, 5u, d);
        colour += sh_term(i, 6u, d);
        colour += sh_term(i, 7u, d);
        colour += sh_term(i, 8u, d);
    }
    if degree >= 3u {
        colour += sh_term(i, 9u, d);
        colour += sh_term(i, 10u, d);
        colour += sh_term(i, 11u, d);
        colour += sh_term(i, 12u, d);
        colour += sh_term(i, 13u, d);
        colour += sh_term(i, 14u, d);
        colour += sh_term(i, 15u, d);
    }
    return colour;
}
