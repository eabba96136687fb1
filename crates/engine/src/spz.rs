//! SPZ export: Niantic's open compressed splat format (version 2), which web viewers such as
//! Spark load; about a tenth of the Inria PLY's size.
//!
//! Layout (all little-endian, then gzip over the whole): a 16-byte header (magic `NGSP`,
//! version, point count, SH degree, fractional bits, flags, a reserved byte), then per-attribute
//! arrays: positions as 24-bit fixed point, opacities as 8-bit sigmoid values, DC colours,
//! log-scales, the quaternion's x, y, z (w >= 0 implied), and the higher SH coefficients, each
//! coefficient's R, G, B together. SPZ stores RUB axes (x right, y up, z back, as OpenGL and
//! three.js); our scenes, like the Inria PLY, are RDF (OpenCV), so y and z are flipped on the
//! way out, with each SH coefficient's sign following the parity of its basis function.

use std::io::Write;

use flate2::Compression;
use flate2::write::GzEncoder;

use crate::model::{GaussianModel, MAX_SH_DEGREE};

pub const SPZ_MAGIC: u32 = 0x5053_474e;
pub const SPZ_VERSION: u32 = 2;
/// DC colours are stored as `0.5 + COLOR_SCALE * dc`: a smaller scale than SH_C0 keeps DC
/// values beyond [0, 1] that higher bands bring back into range.
pub const COLOR_SCALE: f32 = 0.15;
/// Fractional bits of the fixed-point positions for scenes within +-2048 units (1/4096 unit
/// steps); larger scenes get fewer, so no position overflows 24 bits.
const MAX_FRACTIONAL_BITS: u8 = 12;
/// Sign of each higher SH coefficient (3DGS order, degree 1 to 3) when y and z flip: the basis
/// functions odd in y*z-parity change sign (e.g. y, z, xy, xz; not x, yz, xyz).
pub const SH_SIGN_RDF_TO_RUB: [f32; 15] = [
    -1.0, -1.0, 1.0, // y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // xy, yz, 3z^2-1, xz, x^2-y^2
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0,
    1.0, // y(3x^2-y^2), xyz, y(5z^2-1), z(5z^2-3), x(5z^2-1), z(x^2-y^2), x(x^2-3y^2)
];

#[derive(Debug, thiserror::Error)]
pub enum SpzError {
    #[error("SPZ holds SH degree 0 to 3, not {0}")]
    ShDegree(u32),
    #[error("SPZ counts points in 32 bits; {0} Gaussians are too many")]
    TooMany(usize),
    #[error("writing SPZ failed: {0}")]
    Io(#[from] std::io::Error),
}

/// Higher SH coefficients per channel at `degree` (0, 3, 8 or 15).
fn rest_coefficients(degree: u32) -> usize {
    ((degree + 1) * (degree + 1) - 1) as usize
}

/// Writes `model` with SH up to `sh_degree` as gzip-compressed SPZ.
pub fn write_spz<W: Write>(
    model: &GaussianModel,
    sh_degree: u32,
    target: W,
) -> Result<(), SpzError> {
    if sh_degree > MAX_SH_DEGREE {
        return Err(SpzError::ShDegree(sh_degree));
    }
    let count = u32::try_from(model.len()).map_err(|_| SpzError::TooMany(model.len()))?;
    let fractional_bits = fractional_bits(model);
    let rest = rest_coefficients(sh_degree);
    let n = model.len();
    let mut bytes = Vec::with_capacity(16 + n * (9 + 1 + 3 + 3 + 3 + rest * 3));
    bytes.extend_from_slice(&SPZ_MAGIC.to_le_bytes());
    bytes.extend_from_slice(&SPZ_VERSION.to_le_bytes());
    bytes.extend_from_slice(&count.to_le_bytes());
    // SH degree, fractional bits, flags (not antialiased: our renders dilate without the
    // Mip-Splatting opacity compensation), reserved.
    bytes.extend_from_slice(&[sh_degree as u8, fractional_bits, 0, 0]);
    let unit = f32::from(1u16 << fractional_bits);
    for mean in &model.means {
        for value in rdf_to_rub(*mean) {
            let fixed = (value * unit).round() as i32;
            bytes.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
    }
    for &logit in &model.opacity_logits {
        bytes.push(to_byte(sigmoid(logit) * 255.0));
    }
    for coefficients in &model.sh_coefficients {
        for &dc in &coefficients[0] {
            bytes.push(to_byte((dc * COLOR_SCALE + 0.5) * 255.0));
        }
    }
    for scales in &model.log_scales {
        for &log_scale in scales {
            bytes.push(to_byte((log_scale + 10.0) * 16.0));
        }
    }
    for &rotation in &model.rotations {
        for value in quaternion_xyz(rotation) {
            bytes.push(to_byte((value + 1.0) * 127.5));
        }
    }
    for coefficients in &model.sh_coefficients {
        for (index, rgb) in coefficients[1..=rest].iter().enumerate() {
            // Degree 1 keeps 5 bits, higher degrees 4, as the reference encoder does: the lost
            // bits are below what renders show and gzip packs the rest far tighter.
            let bucket = if index < 3 { 8 } else { 16 };
            for &value in rgb {
                bytes.push(quantize_sh(value * SH_SIGN_RDF_TO_RUB[index], bucket));
            }
        }
    }
    let mut encoder = GzEncoder::new(target, Compression::default());
    encoder.write_all(&bytes)?;
    encoder.finish()?;
    Ok(())
}

/// The most fractional bits (at most 12) with which every coordinate fits 24 signed bits.
fn fractional_bits(model: &GaussianModel) -> u8 {
    let largest = model
        .means
        .iter()
        .flatten()
        .filter(|value| value.is_finite())
        .fold(0.0f32, |largest, value| largest.max(value.abs()));
    let limit = ((1 << 23) - 1) as f32;
    (0..=MAX_FRACTIONAL_BITS)
        .rev()
        .find(|&bits| largest * f32::from(1u16 << bits) <= limit)
        .unwrap_or(0)
}

fn rdf_to_rub([x, y, z]: [f32; 3]) -> [f32; 3] {
    [x, -y, -z]
}

/// The unit quaternion's x, y, z with w >= 0, after the axis flip (a half turn about x, which
/// maps (w, x, y, z) to (w, x, -y, -z)).
fn quaternion_xyz([w, x, y, z]: [f32; 4]) -> [f32; 3] {
    let norm = (w * w + x * x + y * y + z * z).sqrt();
    if !(norm.is_finite() && norm > 0.0) {
        return [0.0; 3];
    }
    let sign = if w < 0.0 { -1.0 } else { 1.0 } / norm;
    [x * sign, -y * sign, -z * sign]
}

fn sigmoid(logit: f32) -> f32 {
    1.0 / (1.0 + (-logit).exp())
}

fn to_byte(value: f32) -> u8 {
    value.round().clamp(0.0, 255.0) as u8
}

fn quantize_sh(value: f32, bucket: u32) -> u8 {
    let level = (value * 128.0).round() + 128.0;
    let bucketed = ((level + bucket as f32 / 2.0) / bucket as f32).floor() * bucket as f32;
    to_byte(bucketed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinates_fit_24_bits_at_the_finest_step_that_holds_them() {
        let mut model = GaussianModel::default();
        model.push_simple(
            [1.0, -3.0, 2.0],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            [0.5; 3],
            [0; 3],
        );
        assert_eq!(fractional_bits(&model), 12);
        model.push_simple(
            [5000.0, 0.0, 0.0],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            [0.5; 3],
            [0; 3],
        );
        assert_eq!(fractional_bits(&model), 10);
    }

    #[test]
    fn quaternions_keep_w_non_negative_and_flip_y_and_z() {
        let [x, y, z] = quaternion_xyz([-2.0, 0.0, 0.0, 2.0]);
        let half = std::f32::consts::FRAC_1_SQRT_2;
        assert!((x - 0.0).abs() < 1e-6 && (y - 0.0).abs() < 1e-6 && (z - half).abs() < 1e-6);
        assert_eq!(quaternion_xyz([0.0; 4]), [0.0; 3]);
    }

    #[test]
    fn sh_signs_follow_the_basis_under_the_axis_flip() {
        let mut rng_state = 0x2545_f491_u32;
        let mut next = || {
            rng_state ^= rng_state << 13;
            rng_state ^= rng_state >> 17;
            rng_state ^= rng_state << 5;
            f64::from(rng_state) / f64::from(u32::MAX) * 2.0 - 1.0
        };
        for _ in 0..20 {
            let direction = [next(), next(), next()];
            let flipped = [direction[0], -direction[1], -direction[2]];
            let rdf = crate::reference::sh::basis(3, direction);
            let rub = crate::reference::sh::basis(3, flipped);
            for (index, sign) in SH_SIGN_RDF_TO_RUB.iter().enumerate() {
                let expected = rdf[index + 1] * f64::from(*sign);
                assert!(
                    (rub[index + 1] - expected).abs() < 1e-9,
                    "coefficient {}",
                    index + 1
                );
            }
        }
    }

    #[test]
    fn sh_values_land_on_their_bucket() {
        assert_eq!(quantize_sh(0.0, 16), 128);
        assert_eq!(quantize_sh(1.0, 8), 255);
        assert_eq!(quantize_sh(-1.0, 16), 0);
        assert_eq!(quantize_sh(0.05, 16), 128);
    }
}
