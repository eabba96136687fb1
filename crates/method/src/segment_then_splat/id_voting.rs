//! Stage 2, step 1: give every initial point an object id per level by voting over the views.
//!
//! The released code takes COLMAP keypoint correspondences and lets the last view written win,
//! so the id depends on image order. Here each point collects one vote per view that sees it:
//! the instance id under its projection (0 = "no object" is a vote too). Where the point has
//! COLMAP tracks, only the views that actually observed it vote (occlusion-aware, at the
//! observed pixel); otherwise every view where it lands in front of the camera and inside the
//! image votes. The majority object wins when it holds at least [`VotingRule::min_share`] of the
//! votes and at least [`VotingRule::min_votes`] of them; anything else is "no object". The
//! result is deterministic and independent of view order.

use glam::Vec3;
use rayon::prelude::*;

use super::view_masks::ViewMaskSet;
use segsplat_engine::OBJECT_NONE;
use segsplat_scene::Level;

/// When a point's majority counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VotingRule {
    /// Share of the point's votes the winning object needs (votes for "no object" included).
    pub min_share: f32,
    /// Votes the winning object needs.
    pub min_votes: u32,
}

impl Default for VotingRule {
    fn default() -> Self {
        Self {
            min_share: 0.5,
            min_votes: 2,
        }
    }
}

/// Where a point was seen: the views that observed it, at which pixel (full-resolution frame
/// pixels), or `None` to project it into every view.
pub type Observations<'a> = Option<&'a [(usize, [f32; 2])]>;

/// Object ids for each point at each level; [`OBJECT_NONE`] where no object wins.
pub fn vote_object_ids(
    positions: &[Vec3],
    observations: &[Observations<'_>],
    masks: &ViewMaskSet,
    rule: VotingRule,
) -> Vec<[u32; 3]> {
    positions
        .par_iter()
        .enumerate()
        .map(|(index, &position)| {
            let seen = observations.get(index).copied().flatten();
            let positions = observed_positions(position, seen, masks);
            Level::ALL.map(|level| majority(&positions, masks, level, rule))
        })
        .collect()
}

/// (view, position in mask pixels) for every view that sees the point: the observing views at
/// the observed pixels when `observations` has any, else every view it projects into.
pub(super) fn observed_positions(
    position: Vec3,
    observations: Option<&[(usize, [f32; 2])]>,
    masks: &ViewMaskSet,
) -> Vec<(usize, [f32; 2])> {
    match observations {
        Some(seen) if !seen.is_empty() => seen
            .iter()
            .filter_map(|&(view, pixel)| {
                let frame = masks.views.get(view)?;
                Some((view, frame.position_from_frame_pixel(pixel)?))
            })
            .collect(),
        _ => masks
            .views
            .iter()
            .enumerate()
            .filter_map(|(view, frame)| Some((view, frame.position_of_point(position)?)))
            .collect(),
    }
}

fn majority(
    positions: &[(usize, [f32; 2])],
    masks: &ViewMaskSet,
    level: Level,
    rule: VotingRule,
) -> u32 {
    let mut votes: Vec<u32> = positions
        .iter()
        .map(|&(view, position)| masks.views[view].id_near(level, position))
        .collect();
    if votes.is_empty() {
        return OBJECT_NONE;
    }
    votes.sort_unstable();
    let total = votes.len();
    let (mut best_id, mut best_count) = (0u32, 0usize);
    for run in votes.chunk_by(|a, b| a == b) {
        // Ties go to the smaller id (sorted order), so the result never depends on view order.
        if run.len() > best_count {
            (best_id, best_count) = (run[0], run.len());
        }
    }
    let share = best_count as f32 / total as f32;
    if best_id == 0 || share < rule.min_share || (best_count as u32) < rule.min_votes {
        OBJECT_NONE
    } else {
        best_id
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment_then_splat::view_masks::tests::synthetic_scene;
    use segsplat_scene::synthetic::synthetic_objects;

    /// Which sphere each synthetic point lies on (points are on the sphere surfaces).
    fn true_ids(positions: &[Vec3]) -> Vec<[u32; 3]> {
        let objects = synthetic_objects();
        positions
            .iter()
            .map(|p| {
                let nearest = objects
                    .iter()
                    .min_by(|a, b| {
                        let da = (p.distance(a.center) - a.radius).abs();
                        let db = (p.distance(b.center) - b.radius).abs();
                        da.total_cmp(&db)
                    })
                    .expect("objects");
                nearest.ids
            })
            .collect()
    }

    fn view_masks(scene: &segsplat_scene::Scene) -> ViewMaskSet {
        let frames: Vec<usize> = (0..scene.frames.len()).collect();
        ViewMaskSet::from_user_masks(scene, &frames, None).expect("masks")
    }

    #[test]
    fn tracked_points_take_the_object_their_observations_agree_on() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = synthetic_scene(dir.path(), 12);
        let points = scene.points.clone().expect("points");
        let masks = view_masks(&scene);
        let observed: Vec<Vec<(usize, [f32; 2])>> = points
            .tracks
            .iter()
            .map(|track| {
                track
                    .iter()
                    .map(|o| (o.frame_index as usize, o.pixel))
                    .collect()
            })
            .collect();
        let observations: Vec<Observations> = observed
            .iter()
            .map(|o| (!o.is_empty()).then_some(o.as_slice()))
            .collect();
        let ids = vote_object_ids(
            &points.positions,
            &observations,
            &masks,
            VotingRule::default(),
        );
        let expected = true_ids(&points.positions);
        let tracked = observed.iter().filter(|o| o.len() >= 2).count();
        let right = ids
            .iter()
            .zip(&expected)
            .zip(&observed)
            .filter(|((got, want), seen)| seen.len() >= 2 && got == want)
            .count();
        assert!(tracked > 100, "only {tracked} points have tracks");
        assert!(
            right * 100 >= tracked * 98,
            "{right} of {tracked} tracked points right"
        );
    }

    #[test]
    fn untracked_points_vote_by_projection() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = synthetic_scene(dir.path(), 12);
        let positions = scene.points.clone().expect("points").positions;
        let masks = view_masks(&scene);
        let observations = vec![None; positions.len()];
        let ids = vote_object_ids(&positions, &observations, &masks, VotingRule::default());
        let expected = true_ids(&positions);
        let right = ids.iter().zip(&expected).filter(|(a, b)| a == b).count();
        assert!(
            right * 100 >= positions.len() * 90,
            "{right} of {} right",
            positions.len()
        );
    }

    #[test]
    fn a_point_in_empty_space_gets_no_object() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = synthetic_scene(dir.path(), 12);
        let masks = view_masks(&scene);
        let far_off = [Vec3::new(0.0, 0.0, 3.0)];
        let ids = vote_object_ids(&far_off, &[None], &masks, VotingRule::default());
        assert_eq!(ids[0], [OBJECT_NONE; 3]);
    }
}
