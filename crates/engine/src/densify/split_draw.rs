//! Where a split's children go: a standard normal sample per child, scaled by the parent's
//! scales and rotated by its rotation (3DGS). The samples come from a counter-based generator
//! keyed by (seed, parent, child) rather than a sequential stream, so the GPU pass draws each
//! child's sample in its own thread and still matches the CPU plan draw for draw.
//! `densify_split.wgsl` implements the same functions; change both together.

use glam::{Quat, Vec3};

/// Chris Wellons' "lowbias32" integer hash: cheap, and every output bit depends on every input bit.
pub fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// A uniform draw in (0, 1) from 24 bits of `bits` (never 0, so its log is finite).
fn unit(bits: u32) -> f32 {
    ((bits >> 8) as f32 + 0.5) * (1.0 / 16_777_216.0)
}

/// Three standard normal draws for child `child` of Gaussian `parent` (Box-Muller on four
/// hashed uniforms).
pub fn split_normal(seed: u32, parent: u32, child: u32) -> [f32; 3] {
    let key = hash32(hash32(hash32(seed) ^ parent) ^ child);
    let u = [0u32, 1, 2, 3].map(|k| unit(hash32(key.wrapping_add(k))));
    let tau = std::f32::consts::TAU;
    let radius_a = (-2.0 * u[0].ln()).sqrt();
    let radius_b = (-2.0 * u[2].ln()).sqrt();
    [
        radius_a * (tau * u[1]).cos(),
        radius_a * (tau * u[1]).sin(),
        radius_b * (tau * u[3]).cos(),
    ]
}

/// The world-space offset of a split child from its parent: the draw scaled by the parent's
/// scales, then rotated by its (normalised, w-first) rotation.
pub fn split_offset(
    seed: u32,
    parent: u32,
    child: u32,
    log_scale: [f32; 3],
    rotation_wxyz: [f32; 4],
) -> [f32; 3] {
    let sample = Vec3::from_array(split_normal(seed, parent, child))
        * Vec3::from_array(log_scale.map(f32::exp));
    let [w, x, y, z] = rotation_wxyz;
    let rotation = Quat::from_xyzw(x, y, z, w).normalize();
    (rotation * sample).to_array()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_look_standard_normal_and_differ_by_key() {
        let draws: Vec<f32> = (0..4000u32)
            .flat_map(|parent| split_normal(7, parent, parent % 2))
            .collect();
        let count = draws.len() as f32;
        let mean = draws.iter().sum::<f32>() / count;
        let variance = draws.iter().map(|d| (d - mean).powi(2)).sum::<f32>() / count;
        assert!(mean.abs() < 0.03, "mean {mean}");
        assert!((variance - 1.0).abs() < 0.05, "variance {variance}");
        assert_ne!(split_normal(7, 1, 0), split_normal(7, 1, 1));
        assert_ne!(split_normal(7, 1, 0), split_normal(8, 1, 0));
        assert_eq!(split_normal(7, 1, 0), split_normal(7, 1, 0));
    }
}
