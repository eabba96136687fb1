//! Initial Gaussians: from a sparse point cloud (COLMAP) or at random inside given bounds, as the
//! original 3DGS does: isotropic scales from the mean squared distance to the three nearest
//! neighbours, identity rotations, opacity 0.1, colour in the SH DC term.

use std::num::NonZero;

use glam::Vec3;
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rand::Rng;

use crate::model::{GaussianModel, OBJECT_NONE, SH_C0, SH_COEFFICIENTS};

/// Opacity of every initial Gaussian (3DGS: 0.1).
pub const INITIAL_OPACITY: f32 = 0.1;
/// Smallest squared neighbour distance, so coincident points do not get log(0) scales.
const MIN_NEIGHBOUR_DISTANCE_SQUARED: f32 = 1e-7;
const NEIGHBOURS: usize = 3;

/// Inverse of the logistic sigmoid.
pub fn logit(probability: f32) -> f32 {
    (probability / (1.0 - probability)).ln()
}

/// One Gaussian per point, coloured by `colors` (0..1 RGB), object ids `NONE`.
pub fn gaussians_from_points(positions: &[Vec3], colors: &[Vec3]) -> GaussianModel {
    let scales = neighbour_scales(positions);
    let mut model = GaussianModel::default();
    let opacity_logit = logit(INITIAL_OPACITY);
    for (index, position) in positions.iter().enumerate() {
        let color = colors.get(index).copied().unwrap_or(Vec3::splat(0.5));
        let mut sh = [[0.0f32; 3]; SH_COEFFICIENTS];
        sh[0] = (color - Vec3::splat(0.5))
            .to_array()
            .map(|c| c / SH_C0 as f32);
        let log_scale = scales[index].ln();
        model.means.push(position.to_array());
        model.log_scales.push([log_scale; 3]);
        model.rotations.push([1.0, 0.0, 0.0, 0.0]);
        model.opacity_logits.push(opacity_logit);
        model.sh_coefficients.push(sh);
        model.object_ids.push([OBJECT_NONE; 3]);
    }
    model
}

/// `count` Gaussians uniformly inside the box `[min, max]` with random colours (3DGS's init for
/// datasets without points).
pub fn random_gaussians<R: Rng>(count: usize, min: Vec3, max: Vec3, rng: &mut R) -> GaussianModel {
    let positions: Vec<Vec3> = (0..count)
        .map(|_| {
            let unit = Vec3::new(rng.random(), rng.random(), rng.random());
            min + unit * (max - min)
        })
        .collect();
    let colors: Vec<Vec3> = (0..count)
        .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    gaussians_from_points(&positions, &colors)
}

/// Per point, sqrt of the mean squared distance to its nearest neighbours (excluding itself).
fn neighbour_scales(positions: &[Vec3]) -> Vec<f32> {
    if positions.len() < 2 {
        return vec![1.0; positions.len()];
    }
    let points: Vec<[f32; 3]> = positions.iter().map(|p| p.to_array()).collect();
    // The immutable tree tolerates many points sharing a coordinate (planar clouds), unlike the
    // bucketed mutable one.
    let tree: ImmutableKdTree<f32, u64, 3, 32> = ImmutableKdTree::new_from_slice(&points);
    let wanted = NonZero::new((NEIGHBOURS + 1).min(points.len())).unwrap_or(NonZero::<usize>::MIN);
    points
        .iter()
        .map(|point| {
            let neighbours = tree.nearest_n::<SquaredEuclidean>(point, wanted);
            // The query point itself is among the results at distance 0; skip one zero.
            let mut distances: Vec<f32> = neighbours.iter().map(|n| n.distance).collect();
            distances.sort_by(f32::total_cmp);
            let others = &distances[1..];
            let mean = others.iter().sum::<f32>() / others.len().max(1) as f32;
            mean.max(MIN_NEIGHBOUR_DISTANCE_SQUARED).sqrt()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn scales_follow_neighbour_spacing() {
        // A 5x5 planar grid with spacing 0.5: every point has >= 3 neighbours near 0.5 away
        // (corners: two at 0.5, one at 0.707).
        let positions: Vec<Vec3> = (0..25)
            .map(|i| Vec3::new((i % 5) as f32 * 0.5, (i / 5) as f32 * 0.5, 0.0))
            .collect();
        let model = gaussians_from_points(&positions, &[]);
        for log_scale in &model.log_scales {
            let scale = log_scale[0].exp();
            assert!((0.49..=0.6).contains(&scale), "scale {scale}");
            assert_eq!(log_scale[0], log_scale[2]);
        }
        assert!((model.opacity_logits[0] - logit(0.1)).abs() < 1e-6);
        assert_eq!(model.object_ids[3], [OBJECT_NONE; 3]);
    }

    #[test]
    fn colour_goes_to_sh_dc() {
        let model = gaussians_from_points(&[Vec3::ZERO, Vec3::ONE], &[Vec3::new(1.0, 0.5, 0.0); 2]);
        let dc = model.sh_coefficients[0][0];
        let rendered = dc.map(|c| c * SH_C0 as f32 + 0.5);
        assert!((rendered[0] - 1.0).abs() < 1e-6 && rendered[2].abs() < 1e-6);
    }

    #[test]
    fn random_init_stays_in_bounds_and_is_seeded() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let min = Vec3::new(-1.0, 0.0, 2.0);
        let max = Vec3::new(1.0, 0.5, 3.0);
        let a = random_gaussians(200, min, max, &mut rng);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let b = random_gaussians(200, min, max, &mut rng);
        assert_eq!(a, b);
        for mean in &a.means {
            let p = Vec3::from_array(*mean);
            assert!(p.cmpge(min).all() && p.cmple(max).all());
        }
    }
}
