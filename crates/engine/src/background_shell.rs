//! Background Gaussians (docs/method.md stage 2, step 4): regions no mask covers and the sparse points
//! miss (sky, far walls) need Gaussians of their own, with no object id, or training stretches
//! object Gaussians over them. The released code drops 1000 points at the origin, inside the
//! objects. These sit on a far sphere instead: centred on the cameras, beyond every camera and
//! nearly every sparse point, evenly spread (a Fibonacci lattice), grey until trained.

use glam::Vec3;

use crate::model::{GaussianModel, OBJECT_NONE};
use segsplat_scene::Scene;

/// Shell Gaussians by default (`background_shell` in training configs).
pub const DEFAULT_BACKGROUND_SHELL: usize = 1000;

/// Shell radius in multiples of the farthest camera's distance from the cameras' centre...
const CAMERA_RADIUS_FACTOR: f32 = 3.0;
/// ... or of the sparse points' 99th-percentile distance, whichever is larger.
const POINT_RADIUS_FACTOR: f32 = 1.5;

/// `count` points on the background sphere of `scene` (none for an empty scene or count).
pub fn background_shell_points(scene: &Scene, count: usize) -> Vec<Vec3> {
    if count == 0 || scene.frames.is_empty() {
        return Vec::new();
    }
    let cameras: Vec<Vec3> = scene
        .frames
        .iter()
        .map(|frame| frame.world_from_camera.w_axis.truncate())
        .collect();
    let centre = cameras.iter().copied().sum::<Vec3>() / cameras.len() as f32;
    let camera_radius = cameras
        .iter()
        .map(|camera| camera.distance(centre))
        .fold(0.0f32, f32::max);
    let point_radius = scene.points.as_ref().map_or(0.0, |points| {
        let mut distances: Vec<f32> = points
            .positions
            .iter()
            .map(|point| point.distance(centre))
            .collect();
        distances.sort_unstable_by(f32::total_cmp);
        distances
            .get((distances.len().saturating_sub(1) * 99) / 100)
            .copied()
            .unwrap_or(0.0)
    });
    let radius = (CAMERA_RADIUS_FACTOR * camera_radius)
        .max(POINT_RADIUS_FACTOR * point_radius)
        .max(1.0);
    fibonacci_sphere(count)
        .into_iter()
        .map(|direction| centre + radius * direction)
        .collect()
}

/// Appends one grey Gaussian with no object id per point (scales from the points' own
/// spacing, as any initial Gaussians).
pub fn append_points(model: &mut GaussianModel, points: &[Vec3]) {
    let grey = vec![Vec3::splat(0.5); points.len()];
    let added = crate::init::gaussians_from_points(points, &grey);
    model.means.extend(added.means);
    model.log_scales.extend(added.log_scales);
    model.rotations.extend(added.rotations);
    model.opacity_logits.extend(added.opacity_logits);
    model.sh_coefficients.extend(added.sh_coefficients);
    model
        .object_ids
        .extend(std::iter::repeat_n([OBJECT_NONE; 3], points.len()));
}

/// `count` nearly evenly spaced unit vectors.
fn fibonacci_sphere(count: usize) -> Vec<Vec3> {
    let golden_angle = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    (0..count)
        .map(|index| {
            let z = 1.0 - 2.0 * (index as f32 + 0.5) / count as f32;
            let ring = (1.0 - z * z).max(0.0).sqrt();
            let angle = golden_angle * index as f32;
            Vec3::new(ring * angle.cos(), ring * angle.sin(), z)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use segsplat_scene::synthetic::load_three_spheres;

    #[test]
    fn the_shell_surrounds_cameras_and_points_evenly() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = load_three_spheres(dir.path(), 8, 128, 96).expect("synthetic scene");
        let shell = background_shell_points(&scene, 500);
        assert_eq!(shell.len(), 500);
        let centre = scene
            .frames
            .iter()
            .map(|frame| frame.world_from_camera.w_axis.truncate())
            .sum::<Vec3>()
            / scene.frames.len() as f32;
        let radius = shell[0].distance(centre);
        let farthest_camera = scene
            .frames
            .iter()
            .map(|frame| frame.world_from_camera.w_axis.truncate().distance(centre))
            .fold(0.0f32, f32::max);
        assert!(
            radius >= 2.9 * farthest_camera,
            "{radius} vs {farthest_camera}"
        );
        for point in &shell {
            assert!((point.distance(centre) - radius).abs() < 1e-3 * radius);
        }
        // Even: the mean of the directions is near zero, each hemisphere holds half.
        let mean = shell.iter().map(|p| (*p - centre) / radius).sum::<Vec3>() / 500.0;
        assert!(mean.length() < 0.02, "{mean}");
        let upper = shell.iter().filter(|p| p.y > centre.y).count();
        assert!((230..=270).contains(&upper), "{upper}");
        assert!(background_shell_points(&scene, 0).is_empty());
    }
}
