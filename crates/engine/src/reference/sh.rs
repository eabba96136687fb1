//! Real spherical-harmonic basis (the 3DGS convention and constants) and its gradient with respect
//! to an unnormalised direction's components, in f64.

const C0: f64 = 0.282_094_791_773_878_14;
const C1: f64 = 0.488_602_511_902_919_9;
const C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Number of coefficients used at `degree`.
pub fn coefficient_count(degree: u32) -> usize {
    ((degree.min(3) + 1) * (degree.min(3) + 1)) as usize
}

/// Basis values at unit direction `d` (entries past the degree's count are zero).
pub fn basis(degree: u32, d: [f64; 3]) -> [f64; 16] {
    let [x, y, z] = d;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let all = [
        C0,
        -C1 * y,
        C1 * z,
        -C1 * x,
        C2[0] * x * y,
        C2[1] * y * z,
        C2[2] * (2.0 * zz - xx - yy),
        C2[3] * x * z,
        C2[4] * (xx - yy),
        C3[0] * y * (3.0 * xx - yy),
        C3[1] * x * y * z,
        C3[2] * y * (4.0 * zz - xx - yy),
        C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        C3[4] * x * (4.0 * zz - xx - yy),
        C3[5] * z * (xx - yy),
        C3[6] * x * (xx - 3.0 * yy),
    ];
    let mut out = [0.0; 16];
    let used = coefficient_count(degree);
    out[..used].copy_from_slice(&all[..used]);
    out
}

/// d basis_k / d(x, y, z), treating the components as independent.
pub fn basis_gradient(degree: u32, d: [f64; 3]) -> [[f64; 3]; 16] {
    let [x, y, z] = d;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let all = [
        [0.0, 0.0, 0.0],
        [0.0, -C1, 0.0],
        [0.0, 0.0, C1],
        [-C1, 0.0, 0.0],
        [C2[0] * y, C2[0] * x, 0.0],
        [0.0, C2[1] * z, C2[1] * y],
        [-2.0 * C2[2] * x, -2.0 * C2[2] * y, 4.0 * C2[2] * z],
        [C2[3] * z, 0.0, C2[3] * x],
        [2.0 * C2[4] * x, -2.0 * C2[4] * y, 0.0],
        [6.0 * C3[0] * x * y, C3[0] * (3.0 * xx - 3.0 * yy), 0.0],
        [C3[1] * y * z, C3[1] * x * z, C3[1] * x * y],
        [
            -2.0 * C3[2] * x * y,
            C3[2] * (4.0 * zz - xx - 3.0 * yy),
            8.0 * C3[2] * y * z,
        ],
        [
            -6.0 * C3[3] * x * z,
            -6.0 * C3[3] * y * z,
            C3[3] * (6.0 * zz - 3.0 * xx - 3.0 * yy),
        ],
        [
            C3[4] * (4.0 * zz - 3.0 * xx - yy),
            -2.0 * C3[4] * x * y,
            8.0 * C3[4] * x * z,
        ],
        [2.0 * C3[5] * x * z, -2.0 * C3[5] * y * z, C3[5] * (xx - yy)],
        [C3[6] * (3.0 * xx - 3.0 * yy), -6.0 * C3[6] * x * y, 0.0],
    ];
    let mut out = [[0.0; 3]; 16];
    let used = coefficient_count(degree);
    out[..used].copy_from_slice(&all[..used]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_gradient_matches_finite_differences() {
        let d = [0.3, -0.7, 0.5];
        let analytic = basis_gradient(3, d);
        let eps = 1e-6;
        for axis in 0..3 {
            let mut plus = d;
            let mut minus = d;
            plus[axis] += eps;
            minus[axis] -= eps;
            let (bp, bm) = (basis(3, plus), basis(3, minus));
            for k in 0..16 {
                let numeric = (bp[k] - bm[k]) / (2.0 * eps);
                assert!(
                    (numeric - analytic[k][axis]).abs() < 1e-6,
                    "k={k} axis={axis}: {numeric} vs {}",
                    analytic[k][axis]
                );
            }
        }
    }

    #[test]
    fn degree_limits_coefficients() {
        let b = basis(1, [0.0, 0.0, 1.0]);
        assert_eq!(coefficient_count(1), 4);
        assert!(b[4..].iter().all(|&v| v == 0.0));
        assert!(b[2] > 0.0);
    }
}
