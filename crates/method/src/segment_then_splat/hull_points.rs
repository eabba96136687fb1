//! Stage 2, step 3: Gaussians for objects the sparse cloud missed. An object with (almost) no
//! initial points would never be reconstructed, since no Gaussian carries its id. The released
//! code drops 1000 black points at the origin; here points are carved from the object's visual
//! hull: rays through its mask pixels in the view where it is largest are sampled across the depth
//! range the scene's points occupy in that view, and a sample is kept when the other views that
//! see it agree it lies inside the object's mask. Deterministic (evenly strided pixels and depths).

use std::collections::BTreeMap;

use glam::Vec3;
use rayon::prelude::*;

use super::carved_hulls::CarvedHulls;
use super::view_masks::{ViewMaskSet, ViewMasks};
use segsplat_engine::GaussianModel;
use segsplat_scene::Level;
use segsplat_scene::id_runs::{PixelBounds, id_bounds, id_pixel_counts, id_runs};

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
/// than `fill.min_gaussians` Gaussians. The points of objects `carved` holds (from an earlier
/// carve on the same points, views and fill; see [`CarvedHulls`]) are taken instead of carved
/// again, and the ones carved here are kept there.
///
/// The figurine at 256 px has hundreds of such objects; each used to rescan every view's mask
/// for its area and project every point for its depth range (4.9 s of the job's lost-track merge
/// on two cores, and again when the trainer was built). The areas, vote counts and depth ranges
/// are now counted once (the areas and each object's bounds in every view run by run), and the
/// objects are carved in parallel: the same points, in the same order.
pub fn hull_points_for_missed_objects(
    masks: &ViewMaskSet,
    model: &GaussianModel,
    fill: HullFill,
    carved: &mut CarvedHulls,
) -> Vec<Vec3> {
    carved.carving_from(masks, model, fill);
    let depth_ranges: Vec<std::sync::OnceLock<(f32, f32)>> = masks
        .views
        .iter()
        .map(|_| std::sync::OnceLock::new())
        .collect();
    let mut points = Vec::new();
    for level in Level::ALL {
        let areas = object_areas(masks, level);
        let mut voted: BTreeMap<u32, usize> = BTreeMap::new();
        for ids in &model.object_ids {
            *voted.entry(ids[level.index()]).or_default() += 1;
        }
        let missed: Vec<(u32, usize)> = areas
            .iter()
            .filter(|(id, _)| voted.get(id).copied().unwrap_or(0) < fill.min_gaussians)
            .filter_map(|(&id, per_view)| Some((id, largest_view(per_view)?)))
            .collect();
        // The views' bounds only for a level with objects left to carve: the trainer's model
        // reuses most of the merge's carves.
        let to_carve = missed
            .iter()
            .any(|&(id, _)| carved.get(level, id).is_none());
        let bounds: Vec<Vec<(u32, PixelBounds)>> = if to_carve {
            masks
                .views
                .par_iter()
                .map(|view| id_bounds(view.ids(level), view.width as usize))
                .collect()
        } else {
            Vec::new()
        };
        let fresh: Vec<Option<Vec<Vec3>>> = missed
            .par_iter()
            .map(|&(object_id, source_index)| {
                if carved.get(level, object_id).is_some() {
                    return None;
                }
                let source = &masks.views[source_index];
                let depths = *depth_ranges[source_index].get_or_init(|| depth_range(source, model));
                let pixels = object_pixels(source, level, object_id);
                let object_bounds: Vec<Option<PixelBounds>> = bounds
                    .iter()
                    .map(|view_bounds| {
                        let found = view_bounds.binary_search_by_key(&object_id, |(id, _)| *id);
                        found.ok().map(|index| view_bounds[index].1)
                    })
                    .collect();
                let carve = Carve {
                    stop_early: true,
                    bounds: Some(&object_bounds),
                    ..Carve::asking_every_view(level, object_id, source_index, fill)
                };
                Some(carve_object(masks, carve, &pixels, depths))
            })
            .collect();
        for (&(object_id, _), fresh) in missed.iter().zip(fresh) {
            match fresh {
                Some(object_points) => {
                    points.extend_from_slice(&object_points);
                    carved.keep(level, object_id, object_points);
                }
                None => {
                    points.extend(carved.get(level, object_id).into_iter().flatten());
                    carved.note_reused();
                }
            }
        }
    }
    points
}

/// Per object id of `level` (0, no object, left out): its pixel count in each view.
fn object_areas(masks: &ViewMaskSet, level: Level) -> BTreeMap<u32, Vec<usize>> {
    let views = masks.views.len();
    let mut areas: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (index, view) in masks.views.iter().enumerate() {
        for (id, pixels) in id_pixel_counts(view.ids(level)) {
            areas.entry(id).or_insert_with(|| vec![0; views])[index] = pixels;
        }
    }
    areas
}

/// The pixels of `object_id` in `view` at `level`, ascending.
fn object_pixels(view: &ViewMasks, level: Level, object_id: u32) -> Vec<usize> {
    id_runs(view.ids(level))
        .filter(|(id, _)| *id == object_id)
        .flat_map(|(_, pixels)| pixels)
        .collect()
}

/// The view where an object is largest (the last of equals, as `Iterator::max_by_key` picks),
/// or `None` when it covers no pixel.
fn largest_view(per_view: &[usize]) -> Option<usize> {
    let (index, &area) = per_view.iter().enumerate().max_by_key(|(_, area)| **area)?;
    (area > 0).then_some(index)
}

/// One object's carve: what `inside_hull` asks every view about.
#[derive(Debug, Clone, Copy)]
struct Carve<'a> {
    level: Level,
    object_id: u32,
    source_index: usize,
    fill: HullFill,
    /// Stop asking views once the answer is settled.
    stop_early: bool,
    /// The object's bounds in each view (`None`: not in it), so a sample that projects away
    /// from them is outside without reading the view's ids; `None`: read them always.
    bounds: Option<&'a [Option<PixelBounds>]>,
}

impl Carve<'_> {
    /// The carve that reads every other view's ids for every sample: the plain way.
    fn asking_every_view(
        level: Level,
        object_id: u32,
        source_index: usize,
        fill: HullFill,
    ) -> Self {
        Self {
            level,
            object_id,
            source_index,
            fill,
            stop_early: false,
            bounds: None,
        }
    }
}

/// Carves the object from rays through `pixels`, its pixels in the source view, ascending.
fn carve_object(
    masks: &ViewMaskSet,
    carve: Carve,
    pixels: &[usize],
    (near, far): (f32, f32),
) -> Vec<Vec3> {
    let Carve {
        source_index, fill, ..
    } = carve;
    let source = &masks.views[source_index];
    if pixels.is_empty() {
        return Vec::new();
    }
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
            if inside_hull(masks, carve, point) {
                kept.push(point);
            }
        }
    }
    let keep_every = kept.len().div_ceil(fill.max_points.max(1)).max(1);
    kept.into_iter().step_by(keep_every).collect()
}

/// Whether the views other than `source_index` that see `point` agree it is inside the mask.
/// With `stop_early`, stops as soon as the views left could not bring the agreement up to
/// `fill.min_agreement` even if every one of them saw the point inside: most samples along a
/// ray lie outside the object, and a handful of views settles that (the answer is the same as
/// asking every view, which the tests check).
fn inside_hull(masks: &ViewMaskSet, carve: Carve, point: Vec3) -> bool {
    let Carve {
        level,
        object_id,
        source_index,
        fill,
        stop_early,
        bounds,
    } = carve;
    let others = masks.views.len() - usize::from(source_index < masks.views.len());
    let (mut seen, mut inside, mut asked) = (0usize, 0usize, 0usize);
    for (index, view) in masks.views.iter().enumerate() {
        if index == source_index {
            continue;
        }
        asked += 1;
        if let Some(position) = view.position_of_point(point) {
            seen += 1;
            // `id_near` reads the pixel under the position and the 2 x 2 around it.
            let square = [position[0] - 0.5, position[1] - 0.5].map(|side| side.floor() as i64);
            let near_object = bounds.is_none_or(|bounds| {
                bounds[index].is_some_and(|bounds| bounds.touches_square(square[0], square[1]))
            });
            inside += usize::from(near_object && view.id_near(level, position) == object_id);
            let left = others - asked;
            if stop_early && ((inside + left) as f32) < fill.min_agreement * (seen + left) as f32 {
                return false;
            }
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

    /// The plain way, object by object: every view scanned for the object's area, every point
    /// projected for the source view's depths.
    fn reference_hull_points(
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
                if voted >= fill.min_gaussians {
                    continue;
                }
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
                    continue;
                };
                let depths = depth_range(source, model);
                let pixels: Vec<usize> = source
                    .ids(level)
                    .iter()
                    .enumerate()
                    .filter(|(_, id)| **id == object_id)
                    .map(|(pixel, _)| pixel)
                    .collect();
                let carve = Carve::asking_every_view(level, object_id, source_index, fill);
                points.extend(carve_object(masks, carve, &pixels, depths));
            }
        }
        points
    }

    /// A scene whose third sphere lost its sparse points, its masks, and its model with voted ids
    /// (hull points included).
    fn scene_missing_a_sphere(
        dir: &std::path::Path,
    ) -> (
        ViewMaskSet,
        GaussianModel,
        segsplat_scene::synthetic::SyntheticObject,
    ) {
        let mut scene = synthetic_scene(dir, 12);
        let missing = synthetic_objects()[2];
        scene
            .points
            .as_mut()
            .expect("points")
            .retain(|p| p.distance(missing.center) > missing.radius * 1.05);
        let frames: Vec<usize> = (0..scene.frames.len()).collect();
        let masks = ViewMaskSet::from_user_masks(&scene, &frames, None).expect("masks");
        let config = TrainConfig {
            max_resolution: None,
            ..TrainConfig::default()
        };
        let model = initial_segmented_model(
            &scene,
            &masks,
            &config,
            VotingRule::default(),
            0,
            &mut CarvedHulls::default(),
        )
        .expect("model");
        (masks, model, missing)
    }

    #[test]
    fn hull_points_are_the_plain_ways_points_in_its_order() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (masks, model, _) = scene_missing_a_sphere(dir.path());
        // Fill every object short of 200 Gaussians, so many are carved.
        let fill = HullFill {
            min_gaussians: 200,
            ..HullFill::default()
        };
        let fast =
            hull_points_for_missed_objects(&masks, &model, fill, &mut CarvedHulls::default());
        assert!(!fast.is_empty());
        assert_eq!(fast, reference_hull_points(&masks, &model, fill));
    }

    #[test]
    fn an_object_without_points_gets_points_inside_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (_, model, missing) = scene_missing_a_sphere(dir.path());
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
