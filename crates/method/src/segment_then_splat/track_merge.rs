//! Stage 2, step 2: merge lost tracks. An object that stage 1 lost and found again becomes two
//! ids for one thing; the paper merges two objects of a level when their geometric-appearance
//! distance (Eq. 3) is small:
//!
//! `d = lambda * |centroid_i - centroid_j| / extent + (1 - lambda) * |rgb_i - rgb_j|`
//!
//! with lambda = 0.5, centroids from the object's voted initial points (positions normalised by the
//! scene extent) and mean colours of those points in 0..1, so one threshold serves every scene.
//! Two ids that appear together in one view are different objects by construction, so they are
//! never merged, and neither are groups that would then share a view (union-find over the
//! candidate pairs, closest first, merges chains fully while keeping that guarantee).

use std::collections::{BTreeMap, BTreeSet};

use glam::Vec3;
use rayon::prelude::*;

use super::carved_hulls::CarvedHulls;
use super::id_voting::VotingRule;
use super::training::{SegmentedTrainingError, initial_segmented_model};
use super::view_masks::ViewMaskSet;
use segsplat_engine::model::SH_C0;
use segsplat_engine::schedule::scene_extent;
use segsplat_engine::train::TrainConfig;
use segsplat_engine::{GaussianModel, OBJECT_NONE};
use segsplat_scene::{Level, Scene};

/// When two objects of a level are one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackMergeRule {
    /// Weight of the position term (paper: 0.5); the colour term gets the rest.
    pub position_weight: f32,
    /// Merge below this distance: 0.1 = e.g. the same colour 20% of the extent apart (the two
    /// halves of an object seen from opposite sides have centroids up to its size apart), or the
    /// same place with colours 0.2 apart. Neighbouring look-alikes are kept apart mostly by the
    /// shared-view rule, since neighbours are usually seen together.
    pub max_distance: f32,
}

impl Default for TrackMergeRule {
    fn default() -> Self {
        Self {
            position_weight: 0.5,
            max_distance: 0.1,
        }
    }
}

/// What one object looks like to the merge rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectAppearance {
    pub centroid: Vec3,
    pub color: Vec3,
}

/// Per level, the id each id becomes (only ids that change are listed).
pub type IdRemap = BTreeMap<u32, u32>;

/// Merges lost tracks in `masks`: votes ids onto the scene's initial points, describes every
/// object by its points, and rewrites the id maps with merged ids. Returns the merges per level,
/// and the hull points it carved for objects the points missed that the merge left valid, for
/// the trainer's initial model ([`super::training::segmented_trainer_from_view_masks`]) to reuse.
pub fn merge_lost_tracks(
    scene: &Scene,
    masks: &mut ViewMaskSet,
    config: &TrainConfig,
    rule: TrackMergeRule,
) -> Result<([usize; 3], CarvedHulls), SegmentedTrainingError> {
    let mut carved = CarvedHulls::default();
    let model =
        initial_segmented_model(scene, masks, config, VotingRule::default(), 0, &mut carved)?;
    let centers: Vec<Vec3> = scene
        .frames
        .iter()
        .map(|frame| frame.world_from_camera.w_axis.truncate())
        .collect();
    let extent = scene_extent(&centers);
    let remaps = Level::ALL.map(|level| {
        let appearance = object_appearance(&model, level);
        let views_of = views_of_objects(masks, level);
        merge_ids(&appearance, &views_of, extent, rule)
    });
    carved.forget_remapped(masks, &remaps);
    apply_remaps(masks, &remaps);
    Ok((remaps.map(|remap| remap.len()), carved))
}

/// Centroid and mean colour (SH band 0) of each object's Gaussians at `level`.
pub fn object_appearance(model: &GaussianModel, level: Level) -> BTreeMap<u32, ObjectAppearance> {
    let mut sums: BTreeMap<u32, (Vec3, Vec3, f32)> = BTreeMap::new();
    for (index, ids) in model.object_ids.iter().enumerate() {
        let id = ids[level.index()];
        if id == OBJECT_NONE {
            continue;
        }
        let dc = Vec3::from(model.sh_coefficients[index][0]);
        let color = (dc * SH_C0 as f32 + Vec3::splat(0.5)).clamp(Vec3::ZERO, Vec3::ONE);
        let entry = sums.entry(id).or_insert((Vec3::ZERO, Vec3::ZERO, 0.0));
        entry.0 += Vec3::from(model.means[index]);
        entry.1 += color;
        entry.2 += 1.0;
    }
    sums.into_iter()
        .map(|(id, (position, color, count))| {
            let appearance = ObjectAppearance {
                centroid: position / count,
                color: color / count,
            };
            (id, appearance)
        })
        .collect()
}

/// The views (indices into `masks.views`) each object of `level` appears in.
fn views_of_objects(masks: &ViewMaskSet, level: Level) -> BTreeMap<u32, BTreeSet<usize>> {
    let mut views: BTreeMap<u32, BTreeSet<usize>> = BTreeMap::new();
    for (view_index, view) in masks.views.iter().enumerate() {
        for id in view.objects_at(level) {
            views.entry(id).or_default().insert(view_index);
        }
    }
    views
}

/// Union-find over the pairs closer than the rule allows, closest first, refusing any union of
/// two groups that share a view. Every merged id maps to the smallest id of its group.
pub fn merge_ids(
    appearance: &BTreeMap<u32, ObjectAppearance>,
    views_of: &BTreeMap<u32, BTreeSet<usize>>,
    extent: f32,
    rule: TrackMergeRule,
) -> IdRemap {
    let ids: Vec<u32> = appearance.keys().copied().collect();
    let mut pairs: Vec<(f32, usize, usize)> = Vec::new();
    for (a, id_a) in ids.iter().enumerate() {
        for (b, id_b) in ids.iter().enumerate().skip(a + 1) {
            let distance = distance(&appearance[id_a], &appearance[id_b], extent, rule);
            if distance < rule.max_distance {
                pairs.push((distance, a, b));
            }
        }
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut parent: Vec<usize> = (0..ids.len()).collect();
    let mut group_views: Vec<BTreeSet<usize>> = ids
        .iter()
        .map(|id| views_of.get(id).cloned().unwrap_or_default())
        .collect();
    for (_, a, b) in pairs {
        let (root_a, root_b) = (find(&mut parent, a), find(&mut parent, b));
        if root_a == root_b || !group_views[root_a].is_disjoint(&group_views[root_b]) {
            continue;
        }
        // The smaller index (= smaller id, ids are sorted) stays the root.
        let (keep, absorb) = (root_a.min(root_b), root_a.max(root_b));
        parent[absorb] = keep;
        let absorbed = std::mem::take(&mut group_views[absorb]);
        group_views[keep].extend(absorbed);
    }
    (0..ids.len())
        .filter_map(|index| {
            let root = find(&mut parent, index);
            (root != index).then_some((ids[index], ids[root]))
        })
        .collect()
}

fn distance(a: &ObjectAppearance, b: &ObjectAppearance, extent: f32, rule: TrackMergeRule) -> f32 {
    let position = a.centroid.distance(b.centroid) / extent.max(f32::EPSILON);
    let color = a.color.distance(b.color);
    rule.position_weight * position + (1.0 - rule.position_weight) * color
}

fn find(parent: &mut [usize], mut index: usize) -> usize {
    while parent[index] != index {
        parent[index] = parent[parent[index]];
        index = parent[index];
    }
    index
}

fn apply_remaps(masks: &mut ViewMaskSet, remaps: &[IdRemap; 3]) {
    if remaps.iter().all(BTreeMap::is_empty) {
        return;
    }
    masks.views.par_iter_mut().for_each(|view| {
        for (level, remap) in Level::ALL.into_iter().zip(remaps) {
            view.replace_ids(level, |id| remap.get(&id).copied());
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn object(x: f32, rgb: [f32; 3]) -> ObjectAppearance {
        ObjectAppearance {
            centroid: Vec3::new(x, 0.0, 0.0),
            color: Vec3::from(rgb),
        }
    }

    fn views(entries: &[(u32, &[usize])]) -> BTreeMap<u32, BTreeSet<usize>> {
        entries
            .iter()
            .map(|(id, views)| (*id, views.iter().copied().collect()))
            .collect()
    }

    #[test]
    fn a_lost_and_refound_object_merges_into_its_first_id_and_chains_merge_fully() {
        let red = [0.9, 0.1, 0.1];
        let appearance: BTreeMap<u32, ObjectAppearance> = [
            (1, object(0.0, red)),
            (4, object(0.05, red)),
            (7, object(0.1, red)),
            (2, object(2.0, [0.1, 0.1, 0.9])),
        ]
        .into_iter()
        .collect();
        let seen = views(&[(1, &[0, 1]), (4, &[2, 3]), (7, &[4]), (2, &[0, 2, 4])]);
        let remap = merge_ids(&appearance, &seen, 4.0, TrackMergeRule::default());
        assert_eq!(remap, [(4, 1), (7, 1)].into_iter().collect());
    }

    #[test]
    fn objects_seen_together_or_far_apart_stay_separate() {
        let red = [0.9, 0.1, 0.1];
        let appearance: BTreeMap<u32, ObjectAppearance> = [
            (1, object(0.0, red)),
            (2, object(0.01, red)),
            (3, object(3.0, red)),
            (5, object(0.0, [0.1, 0.9, 0.1])),
        ]
        .into_iter()
        .collect();
        // 1 and 2 look alike but share view 0; 3 is far; 5 has another colour.
        let seen = views(&[(1, &[0]), (2, &[0, 1]), (3, &[2]), (5, &[3])]);
        let remap = merge_ids(&appearance, &seen, 4.0, TrackMergeRule::default());
        assert!(remap.is_empty(), "{remap:?}");
    }

    #[test]
    fn a_track_renamed_in_half_the_views_is_merged_back() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = crate::segment_then_splat::view_masks::tests::synthetic_scene(dir.path(), 12);
        let config = TrainConfig {
            max_resolution: None,
            ..TrainConfig::default()
        };
        let frames: Vec<usize> = (0..scene.frames.len()).collect();
        let mut masks = ViewMaskSet::from_user_masks(&scene, &frames, None).expect("masks");
        // Sphere 1 (small id 1) is "lost" after view 5 and "found again" as id 9.
        masks.rename_from_view(6, Level::Small, 1, 9);
        let merges = merge_lost_tracks(&scene, &mut masks, &config, TrackMergeRule::default())
            .map(|(merges, _)| merges)
            .expect("merge");
        assert_eq!(merges, [1, 0, 0]);
        assert!(
            masks
                .views
                .iter()
                .all(|view| !view.ids(Level::Small).contains(&9))
        );
        assert!(masks.views[8].ids(Level::Small).contains(&1));
    }

    #[test]
    fn synthetic_scene_objects_are_not_merged() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = crate::segment_then_splat::view_masks::tests::synthetic_scene(dir.path(), 12);
        let config = TrainConfig {
            max_resolution: None,
            ..TrainConfig::default()
        };
        let frames: Vec<usize> = (0..scene.frames.len()).collect();
        let mut masks = ViewMaskSet::from_user_masks(&scene, &frames, None).expect("masks");
        let merges = merge_lost_tracks(&scene, &mut masks, &config, TrackMergeRule::default())
            .map(|(merges, _)| merges)
            .expect("merge");
        assert_eq!(merges, [0, 0, 0]);
    }
}
