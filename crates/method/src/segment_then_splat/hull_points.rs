//! Stage 2, step 3: Gaussians for objects the sparse cloud missed. An object with (almost) no
//! initial points would never be reconstructed, since no Gaussian carries its id. The released
//! code drops 1000 black points at the origin; here points are carved from the object's visual
//! hull: rays through its mask pixels in the view where it is largest are sampled across the depth
//! range the scene's points occupy in that view, and a sample is kept when the other views that
//! see it agree it lies inside the object's mask. Deterministic (evenly strided pixels and depths).

use glam::Vec3;

use super::view_masks::{ViewMaskSet, ViewMasks};
use segsplat_engine::GaussianModel;
use segsplat_scene::Level;

/// How missed objects are filled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HullFill {
    /// Objects with fewer voted Gaussians than this get hull points.
    pub min_gaussians: usize,
    /// Mask pixels (rays) tried per object.
    pub rays: usize,
    /// Depths sampled along each ray.
    pub depth_samples: usize,
    /// Share of the views seeing a sample that must put it inside the object's mask.
    pub min_agreement: f32,
    /// Views (besides the ray's) that must see a sample.
    pub min_views: usize,
    /// Points kept per object at most.
    pub max_points: usize,
}

impl Default for HullFill {
    fn default() -> Self {
        Self {
            min_gaussians: 3,
            rays: 256,
            depth_samples: 48,
            min_agreement: 0.75,
            min_views: 2,
            max_points: 200,
        }
    }
}

/// Hull points for every object of every level that `model` (with voted ids) leaves with fewer
/// than `fill.min_gaussians` Gaussians.
pub fn hull_points_for_missed_objects(
    masks: &ViewMaskSet,
    model: &GaussianModel,
    fill: HullFill,
) -> Vec<Vec3> {
    let mut points = Vec::new();
    for level in Level::ALL {
        let mut present: Vec<u32> = masks
            .views
            .iter()
            .flat_map(|view| view.objects_at(level))
            .collect();
        present.sort_unstable();
        present.dedup();
        for object_id in present {
            let voted = model
                .object_ids
                .iter()
                .filter(|ids| ids[level.index()] == object_id)
                .count();
            if voted < fill.min_gaussians {
                points.extend(carve_object(masks, model, level, object_id, fill));
            }
        }
    }
    points
}

fn carve_object(
    masks: &ViewMaskSet,
    model: &GaussianModel,
    level: Level,
    object_id: u32,
    fill: HullFill,
) -> Vec<Vec3> {
    let area = |view: &ViewMasks| {
        view.ids(level)
            .iter()
            .filter(|&&id| id == object_id)
            .count()
    };
    let Some((source_index, source)) = masks
        .views
        .iter()
        .enumerate()
        .max_by_key(|(_, view)| area(view))
    else {
        return Vec::new();
    };
    let pixels: Vec<usize> = source
        .ids(level)
        .iter()
        .enumerate()
        .filter(|(_, id)| **id == object_id)
        .map(|(pixel, _)| pixel)
        .collect();
    if pixels.is_empty() {
        return Vec::new();
    }
    let (near, far) = depth_range(source, model);
    let world_from_camera = source.camera.camera_from_world.inverse();
    let origin = world_from_camera.transform_point3(Vec3::ZERO);
    let stride = pixels.len().div_ceil(fill.rays.max(1)).max(1);
    let mut kept = Vec::new();
    for &pixel in pixels.iter().step_by(stride) {
        let (x, y) = (pixel % source.width as usize, pixel / source.width as usize);
        let camera = &source.camera;
        let direction_in_camera = Vec3::new(
            (x as f32 + 0.5 - camera.cx) / camera.fx,
            (y as f32 + 0.5 - camera.cy) / camera.fy,
            1.0,
        );
        let direction = world_from_camera.transform_vector3(direction_in_camera);
        for sample in 0..fill.depth_samples {
            let t = (sample as f32 + 0.5) / fill.depth_samples as f32;
            let depth = near + t * (far - near);
            let point = origin + direction * depth;
            if inside_hull(masks, source_index, level, object_id, point, fill) {
                kept.push(point);
            }
        }
    }
    let keep_every = kept.len().div_ceil(fill.max_points.max(1)).max(1);
    kept.into_iter().step_by(keep_every).collect()
}

/// Whether the views other than `source_index` that see `point` agree it is inside the mask.
fn inside_hull(
    masks: &ViewMaskSet,
    source_index: usize,
    level: Level,
    object_id: u32,
    point: Vec3,
    fill: HullFill,
) -> bool {
    let (mut seen, mut inside) = (0usize, 0usize);
    for (index, view) in masks.views.iter().enumerate() {
        if index == source_index {
            continue;
        }
        if let Some(position) = view.position_of_point(point) {
            seen += 1;
            inside += usize::from(view.id_near(level, position) == object_id);
        }
    }
    seen >= fill.min_views && inside as f32 >= fill.min_agreement * seen as f32
}

/// The camera depths the scene's points occupy in `view` (5th to 95th percentile, widened by a
/// quarter each way), or a generic range when no point is in view.
fn depth_range(view: &ViewMasks, model: &GaussianModel) -> (f32, f32) {
    let mut depths: Vec<f32> = model
        .means
        .iter()
        .filter_map(|mean| {
            let point = Vec3::from(*mean);
            view.position_of_point(point)?;
            Some(view.camera.camera_from_world.transform_point3(point).z)
        })
        .collect();
    if depths.len() < 2 {
        return (0.1, 100.0);
    }
    depths.sort_unstable_by(f32::total_cmp);
    let at = |q: f32| depths[((depths.len() - 1) as f32 * q) as usize];
    let (low, high) = (at(0.05), at(0.95));
    let margin = 0.25 * (high - low);
    ((low - margin).max(view.camera.near), high + margin)
}

/// Appends `points` to `model` as grey Gaussians (colour is learned) with no object ids yet.
#[doc(inline)]
pub use segsplat_engine::background_shell::append_points;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment_then_splat::id_voting::VotingRule;
    use crate::segment_then_splat::training::initial_segmented_model;
    use crate::segment_then_splat::view_masks::tests::synthetic_scene;
    use segsplat_engine::train::TrainConfig;
    use segsplat_scene::synthetic::synthetic_objects;

    #[test]
    fn an_object_without_points_gets_points_inside_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut scene = synthetic_scene(dir.path(), 12);
        let missing = synthetic_objects()[2];
        let mut points = scene.points.take().expect("points");
        let keep: Vec<bool> = points
            .positions
            .iter()
            .map(|p| p.distance(missing.center) > missing.radius * 1.05)
            .collect();
        fn filter<T>(values: &mut Vec<T>, keep: &[bool]) {
            let mut flags = keep.iter();
            values.retain(|_| *flags.next().unwrap_or(&true));
        }
        filter(&mut points.positions, &keep);
        filter(&mut points.colors, &keep);
        filter(&mut points.tracks, &keep);
        scene.points = Some(points);
        let frames: Vec<usize> = (0..scene.frames.len()).collect();
        let masks = ViewMaskSet::from_user_masks(&scene, &frames, None).expect("masks");
        let config = TrainConfig {
            max_resolution: None,
            ..TrainConfig::default()
        };
        let model = initial_segmented_model(&scene, &masks, &config, VotingRule::default(), 0)
            .expect("model");
        let small_id = missing.ids[0];
        let members: Vec<Vec3> = model
            .object_ids
            .iter()
            .zip(&model.means)
            .filter(|(ids, _)| ids[0] == small_id)
            .map(|(_, mean)| Vec3::from(*mean))
            .collect();
        eprintln!(
            "{} hull Gaussians, {} within 1.5 radii",
            members.len(),
            members
                .iter()
                .filter(|p| p.distance(missing.center) < missing.radius * 1.5)
                .count()
        );
        assert!(members.len() >= 10, "only {} Gaussians", members.len());
        let close = members
            .iter()
            .filter(|p| p.distance(missing.center) < missing.radius * 1.5)
            .count();
        assert!(
            close * 10 >= members.len() * 9,
            "{close} of {} hull points near the sphere",
            members.len()
        );
    }
}
