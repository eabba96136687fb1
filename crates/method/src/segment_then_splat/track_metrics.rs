//! Stage 1's quality against ground truth, the paper's Table 3c: ORR (object recall rate) and
//! Dup (duplicated objects), from predicted and true id maps of the same views at one level.

use std::collections::HashMap;

use super::view_masks::ViewMaskSet;
use segsplat_scene::Level;

#[derive(Debug, thiserror::Error)]
pub enum TrackMetricError {
    #[error("frame {frame_index} has ground truth but no predicted masks")]
    MissingView { frame_index: usize },
    #[error("frame {frame_index}: predicted masks are {predicted:?}, the truth {truth:?}")]
    SizeMismatch {
        frame_index: usize,
        predicted: [u32; 2],
        truth: [u32; 2],
    },
}

/// ORR and Dup of one level.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackQuality {
    /// Ground-truth objects (ids present in any true view).
    pub truth_objects: usize,
    /// Ground-truth objects some predicted object recalls.
    pub recalled_objects: usize,
    /// `recalled_objects / truth_objects` (1 when there are none).
    pub object_recall_rate: f64,
    /// Dup: ground-truth objects with more than one predicted track.
    pub duplicated_objects: usize,
}

/// Pixel counts pooled over views.
#[derive(Debug, Clone, Copy, Default)]
struct Pooled {
    intersection: u64,
    union: u64,
}

impl Pooled {
    fn iou(self) -> f64 {
        if self.union == 0 {
            0.0
        } else {
            self.intersection as f64 / self.union as f64
        }
    }
}

/// ORR and Dup at `level`, comparing every true view with the predicted view of the same frame.
///
/// - A ground-truth object is *recalled* by a predicted object when their IoU, pooled over the
///   views where the true object appears (summed intersections over summed unions, so a view
///   where the prediction is missing counts fully against it), is above `iou_threshold`. ORR
///   is the fraction of true objects recalled by at least one predicted object.
/// - A predicted object is a *track* of a true object when their IoU pooled over the views where
///   both appear is above `iou_threshold`: it follows that object wherever it exists, however
///   briefly. Dup counts the true objects with two or more tracks (an object split into several
///   identities across views), as a number of objects.
pub fn object_recall_and_duplicates(
    predicted: &ViewMaskSet,
    truth: &ViewMaskSet,
    level: Level,
    iou_threshold: f64,
) -> Result<TrackQuality, TrackMetricError> {
    // Per view: true areas, predicted areas, and the joint counts of overlapping pairs.
    let mut per_view = Vec::with_capacity(truth.views.len());
    for true_view in &truth.views {
        let frame_index = true_view.frame_index;
        let predicted_view = predicted
            .view_of_frame(frame_index)
            .ok_or(TrackMetricError::MissingView { frame_index })?;
        if (predicted_view.width, predicted_view.height) != (true_view.width, true_view.height) {
            return Err(TrackMetricError::SizeMismatch {
                frame_index,
                predicted: [predicted_view.width, predicted_view.height],
                truth: [true_view.width, true_view.height],
            });
        }
        per_view.push(ViewCounts::new(
            true_view.ids(level),
            predicted_view.ids(level),
        ));
    }
    let mut truth_ids: Vec<u32> = per_view
        .iter()
        .flat_map(|counts| counts.truth.keys().copied())
        .collect();
    truth_ids.sort_unstable();
    truth_ids.dedup();
    let mut candidates: Vec<(u32, u32)> = per_view
        .iter()
        .flat_map(|counts| counts.joint.keys().copied())
        .collect();
    candidates.sort_unstable();
    candidates.dedup();
    let (mut recalled, mut tracks) = (HashMap::new(), HashMap::<u32, usize>::new());
    for (true_id, predicted_id) in candidates {
        let (mut where_true, mut where_both) = (Pooled::default(), Pooled::default());
        for counts in &per_view {
            let Some(&true_area) = counts.truth.get(&true_id) else {
                continue;
            };
            let predicted_area = counts.predicted.get(&predicted_id).copied().unwrap_or(0);
            let intersection = counts
                .joint
                .get(&(true_id, predicted_id))
                .copied()
                .unwrap_or(0);
            let union = true_area + predicted_area - intersection;
            where_true.intersection += intersection;
            where_true.union += union;
            if predicted_area > 0 {
                where_both.intersection += intersection;
                where_both.union += union;
            }
        }
        if where_true.iou() > iou_threshold {
            recalled.insert(true_id, true);
        }
        if where_both.iou() > iou_threshold {
            *tracks.entry(true_id).or_default() += 1;
        }
    }
    let truth_objects = truth_ids.len();
    let recalled_objects = recalled.len();
    Ok(TrackQuality {
        truth_objects,
        recalled_objects,
        object_recall_rate: if truth_objects == 0 {
            1.0
        } else {
            recalled_objects as f64 / truth_objects as f64
        },
        duplicated_objects: tracks.values().filter(|&&count| count > 1).count(),
    })
}

/// One view's pixel counts per true id, per predicted id, and per overlapping pair.
struct ViewCounts {
    truth: HashMap<u32, u64>,
    predicted: HashMap<u32, u64>,
    joint: HashMap<(u32, u32), u64>,
}

impl ViewCounts {
    fn new(truth_ids: &[u32], predicted_ids: &[u32]) -> Self {
        let mut counts = Self {
            truth: HashMap::new(),
            predicted: HashMap::new(),
            joint: HashMap::new(),
        };
        for (&true_id, &predicted_id) in truth_ids.iter().zip(predicted_ids) {
            if true_id != 0 {
                *counts.truth.entry(true_id).or_default() += 1;
            }
            if predicted_id != 0 {
                *counts.predicted.entry(predicted_id).or_default() += 1;
            }
            if true_id != 0 && predicted_id != 0 {
                *counts.joint.entry((true_id, predicted_id)).or_default() += 1;
            }
        }
        counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment_then_splat::view_masks::tests::synthetic_scene;

    #[test]
    fn truth_against_itself_recalls_all_and_a_split_object_is_a_duplicate() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = synthetic_scene(dir.path(), 6);
        let frames: Vec<usize> = (0..6).collect();
        let truth = ViewMaskSet::from_user_masks(&scene, &frames, Some(32)).expect("masks");
        let same = object_recall_and_duplicates(&truth, &truth, Level::Small, 0.5).expect("ok");
        assert_eq!(same.truth_objects, 3);
        assert_eq!(same.object_recall_rate, 1.0);
        assert_eq!(same.duplicated_objects, 0);

        // Object 1 renamed 9 in the last view: two tracks; the first still recalls it.
        let mut split = truth.clone();
        for view in split.views.iter_mut().skip(5) {
            for level in Level::ALL {
                view.replace_ids(level, |id| (id == 1).then_some(9));
            }
        }
        let quality = object_recall_and_duplicates(&split, &truth, Level::Small, 0.5).expect("ok");
        assert_eq!(quality.duplicated_objects, 1);
        assert_eq!(quality.recalled_objects, 3);
    }

    /// Stage 1's propagation on the moving-discs sequence, scored by this module's ORR and Dup.
    #[test]
    fn object_recall_and_duplicates_on_the_sequence() {
        use crate::segment_then_splat::view_masks::ViewMasks;
        use segsplat_vision::segment::propagation::test_support::{FRAMES, run, truth_ids};

        let (propagation, _) = run();
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = synthetic_scene(dir.path(), FRAMES);
        let views = |ids: &dyn Fn(usize) -> [Vec<u32>; 3]| ViewMaskSet {
            views: (0..FRAMES)
                .map(|frame| {
                    ViewMasks::without_objects(&scene, frame, None)
                        .and_then(|view| view.with_level_ids(ids(frame)))
                        .expect("128 x 96 views")
                })
                .collect(),
        };
        let predicted = views(&|frame| propagation.frames[frame].clone());
        let truth = views(&truth_ids);
        for level in Level::ALL {
            let quality =
                object_recall_and_duplicates(&predicted, &truth, level, 0.5).expect("same views");
            println!(
                "{level:?}: ORR {:.3} ({} of {}), Dup {}",
                quality.object_recall_rate,
                quality.recalled_objects,
                quality.truth_objects,
                quality.duplicated_objects
            );
            assert_eq!(quality.object_recall_rate, 1.0);
            assert_eq!(quality.duplicated_objects, 0);
        }
    }
}
