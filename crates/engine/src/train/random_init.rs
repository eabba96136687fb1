//! The initial Gaussians of a scene without sparse points: random points where the cameras can
//! see them.
//!
//! 3DGS draws them uniformly in a box. For a capture, the box around the cameras holds the
//! cameras too, and a point just in front of one camera covers a large part of that camera's
//! image while the others see it small or not at all: it is cheapest for the optimiser to paint
//! that one view on it, and it stays there as a floater that other views see as a blob (a
//! nerfstudio phone capture without points: one held-out view 15.9 dB against 26.6 for another).
//! So a candidate is kept only where enough cameras see it, in front of them and inside their
//! images, and not close to any of them.

use glam::{Mat4, Vec3};
use rand::Rng;

use crate::GaussianModel;
use crate::init::random_gaussians;
use crate::schedule::scene_extent;
use segsplat_scene::{Frame, Scene, SceneFormat};

/// Share of the cameras that must see a random initial point.
const MIN_VIEW_SHARE: f32 = 0.1;
/// How close to a camera centre a random initial point may be, as a share of the scene extent
/// (1.1 x the largest camera distance from the cameras' centroid).
const NEAR_SHARE: f32 = 0.1;
/// Candidates drawn per point wanted before giving up on filling the count.
const CANDIDATES_PER_POINT: usize = 50;

/// One camera as the visibility test needs it.
struct Seer {
    camera_from_world: Mat4,
    centre: Vec3,
    focal: [f32; 2],
    principal: [f32; 2],
    size: [f32; 2],
}

impl Seer {
    fn of(frame: &Frame) -> Self {
        let intrinsics = &frame.intrinsics;
        Self {
            camera_from_world: frame.world_from_camera.inverse(),
            centre: frame.world_from_camera.w_axis.truncate(),
            focal: [intrinsics.fx as f32, intrinsics.fy as f32],
            principal: [intrinsics.cx as f32, intrinsics.cy as f32],
            size: [intrinsics.width as f32, intrinsics.height as f32],
        }
    }

    fn sees(&self, point: Vec3) -> bool {
        let local = self.camera_from_world.transform_point3(point);
        if local.z <= 0.0 {
            return false;
        }
        let x = self.focal[0] * local.x / local.z + self.principal[0];
        let y = self.focal[1] * local.y / local.z + self.principal[1];
        (0.0..self.size[0]).contains(&x) && (0.0..self.size[1]).contains(&y)
    }
}

/// `count` random Gaussians with random colours in the scene's bounds, each seen by at least
/// [`MIN_VIEW_SHARE`] of the cameras and no nearer than [`NEAR_SHARE`] of the scene extent to
/// any camera. Fewer when the cameras see too little of the bounds to fill the count; the plain
/// box when they see none of it.
pub fn random_visible_gaussians<R: Rng>(scene: &Scene, count: usize, rng: &mut R) -> GaussianModel {
    let (min, max) = random_init_bounds(scene);
    let seers: Vec<Seer> = scene.frames.iter().map(Seer::of).collect();
    let needed = ((seers.len() as f32 * MIN_VIEW_SHARE).ceil() as usize).max(1);
    let centres: Vec<Vec3> = seers.iter().map(|seer| seer.centre).collect();
    let near = NEAR_SHARE * scene_extent(&centres);
    let mut kept = Vec::with_capacity(count);
    for _ in 0..count.saturating_mul(CANDIDATES_PER_POINT) {
        if kept.len() == count {
            break;
        }
        let unit = Vec3::new(rng.random(), rng.random(), rng.random());
        let point = min + unit * (max - min);
        if seers.iter().any(|seer| seer.centre.distance(point) < near) {
            continue;
        }
        if seers.iter().filter(|seer| seer.sees(point)).count() >= needed {
            kept.push(point);
        }
    }
    if kept.is_empty() {
        return random_gaussians(count, min, max, rng);
    }
    let colors: Vec<Vec3> = kept
        .iter()
        .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    crate::init::gaussians_from_points(&kept, &colors)
}

/// The box random initial points are drawn in: 3DGS's cube for Blender scenes, else a cube
/// around the cameras' centroid as wide as the scene extent.
pub fn random_init_bounds(scene: &Scene) -> (Vec3, Vec3) {
    if scene.format == SceneFormat::Blender {
        return (Vec3::splat(-1.3), Vec3::splat(1.3));
    }
    let centres = camera_centres(scene);
    let extent = scene_extent(&centres);
    let centre = centres.iter().copied().sum::<Vec3>() / centres.len().max(1) as f32;
    (centre - Vec3::splat(extent), centre + Vec3::splat(extent))
}

/// Whether the scene brings sparse points to start from (else training starts from random ones).
pub fn has_sparse_points(scene: &Scene) -> bool {
    scene
        .points
        .as_ref()
        .is_some_and(|points| !points.positions.is_empty())
}

/// Every frame's camera centre.
pub fn camera_centres(scene: &Scene) -> Vec<Vec3> {
    scene
        .frames
        .iter()
        .map(|frame| frame.world_from_camera.w_axis.truncate())
        .collect()
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use segsplat_scene::SparsePoints;
    use segsplat_scene::synthetic::{
        SyntheticSpec, synthetic_intrinsics, synthetic_world_from_cameras,
    };

    use super::*;

    /// The synthetic orbit's cameras (a ring of radius 4 looking at the origin), no points.
    fn orbit_scene() -> Scene {
        let spec = SyntheticSpec {
            frame_count: 12,
            ..SyntheticSpec::default()
        };
        let frames = synthetic_world_from_cameras(&spec)
            .into_iter()
            .enumerate()
            .map(|(index, world_from_camera)| Frame {
                name: format!("{index}.png"),
                image_path: format!("images/{index}.png").into(),
                intrinsics: synthetic_intrinsics(&spec),
                world_from_camera,
                time: None,
                source_id: None,
                split: None,
            })
            .collect();
        Scene {
            root: "/nonexistent".into(),
            format: SceneFormat::Colmap,
            frames,
            points: None,
            masks: None,
            background: [0.0; 3],
        }
    }

    #[test]
    fn random_points_are_seen_by_enough_cameras_and_keep_clear_of_them() {
        let scene = orbit_scene();
        let model = random_visible_gaussians(&scene, 2_000, &mut ChaCha8Rng::seed_from_u64(7));
        assert_eq!(model.len(), 2_000, "the cameras see enough of the box");
        let centres = camera_centres(&scene);
        let near = NEAR_SHARE * scene_extent(&centres);
        let needed = (scene.frames.len() as f32 * MIN_VIEW_SHARE).ceil() as usize;
        for point in &model.means {
            let point = Vec3::from(*point);
            assert!(centres.iter().all(|centre| centre.distance(point) >= near));
            let seen = scene
                .frames
                .iter()
                .filter(|frame| Seer::of(frame).sees(point))
                .count();
            assert!(seen >= needed, "{point} seen by {seen} cameras");
        }
        // The plain box would have put many points where no camera looks (behind the ring).
        let (min, max) = random_init_bounds(&scene);
        let boxed = random_gaussians(2_000, min, max, &mut ChaCha8Rng::seed_from_u64(7));
        let outside_ring = boxed
            .means
            .iter()
            .filter(|point| Vec3::from(**point).truncate().length() > 4.0)
            .count();
        assert!(outside_ring > 500, "{outside_ring}");
    }

    #[test]
    fn sparse_points_are_told_apart_from_none() {
        let mut scene = orbit_scene();
        assert!(!has_sparse_points(&scene));
        scene.points = Some(SparsePoints::default());
        assert!(
            !has_sparse_points(&scene),
            "an empty point file is no points"
        );
        scene.points = Some(SparsePoints {
            positions: vec![Vec3::ZERO],
            colors: vec![Vec3::ONE],
            ..SparsePoints::default()
        });
        assert!(has_sparse_points(&scene));
    }
}
