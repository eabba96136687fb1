//! Stages 2 and 3 put together: object ids on the initial Gaussians, then a trainer that
//! optimises with the object loss, keeps every object alive (persistence floor) and filters
//! partial masks late in training.

use super::association::{
    AssociationError, AssociationOptions, AssociationReport, generated_view_masks,
};
use super::background_shell::background_shell_points;
use super::carved_hulls::CarvedHulls;
use super::hull_points::{HullFill, append_points, hull_points_for_missed_objects};
use super::id_voting::{Observations, VotingRule, vote_object_ids};
use super::track_merge::{TrackMergeRule, merge_lost_tracks};
use super::view_masks::{ViewMaskSet, ViewMaskSetError};
use segsplat_engine::GaussianModel;
use segsplat_engine::densify::ObjectFloor;
use segsplat_engine::train::trainer::{initial_model, resolve_adapter_sized};
use segsplat_engine::train::views::is_held_out;
use segsplat_engine::train::{
    ObjectLossConfig, ObjectTargets, TrainConfig, TrainError, Trainer, ViewIdMaps,
};
use segsplat_gpu::GpuContext;
use segsplat_scene::{Level, Scene, SparsePoints};
use segsplat_vision::segment::MaskGenerator;

/// Gaussians each object keeps at least (small, middle, large), or all it has when fewer: the
/// released code's intended floors.
pub const DEFAULT_OBJECT_FLOORS: [usize; 3] = [1000, 1000, 10];

#[derive(Debug, thiserror::Error)]
pub enum SegmentedTrainingError {
    #[error(transparent)]
    Masks(#[from] ViewMaskSetError),
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error(transparent)]
    Association(#[from] AssociationError),
    #[error(
        "training view {train_view} is frame {trainer_frame}, but its masks are frame {mask_frame}"
    )]
    ViewOrder {
        train_view: usize,
        trainer_frame: usize,
        mask_frame: usize,
    },
}

/// How the segmented training is set up beyond the plain training config.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentedTrainingOptions {
    pub voting: VotingRule,
    pub object_floors: [usize; 3],
    /// Background Gaussians (no object) on a far sphere around the scene.
    pub background_shell: usize,
}

/// Background shell Gaussians by default (the released code's count, placed far away rather
/// than at the origin).
pub use segsplat_engine::background_shell::DEFAULT_BACKGROUND_SHELL;

impl Default for SegmentedTrainingOptions {
    fn default() -> Self {
        Self {
            voting: VotingRule::default(),
            object_floors: DEFAULT_OBJECT_FLOORS,
            background_shell: DEFAULT_BACKGROUND_SHELL,
        }
    }
}

/// The frames the trainer trains on, in its order.
pub fn training_frames(scene: &Scene, config: &TrainConfig) -> Vec<usize> {
    (0..scene.frames.len())
        .filter(|&index| !is_held_out(scene, index, config.eval_split_every))
        .collect()
}

/// The initial model with object ids voted from the training views' masks. Sparse points vote
/// with their tracks where they have them (the views that really saw them). The hull points of
/// objects `carved` holds from an earlier carve (the lost-track merge's) are reused, and the ones
/// carved here are kept in it; pass an empty [`CarvedHulls`] to carve everything.
pub fn initial_segmented_model(
    scene: &Scene,
    masks: &ViewMaskSet,
    config: &TrainConfig,
    voting: VotingRule,
    background_shell: usize,
    carved: &mut CarvedHulls,
) -> Result<GaussianModel, SegmentedTrainingError> {
    let mut model = initial_model(scene, config)?;
    let masks = &voting_views(scene, masks);
    // Tracks in mask-view indices; only meaningful when the model is the sparse points in order.
    let tracks = match &scene.points {
        Some(points) if points.positions.len() == model.len() => {
            point_tracks_in_views(points, masks)
        }
        _ => vec![Vec::new(); model.len()],
    };
    let observations: Vec<Observations> = tracks
        .iter()
        .map(|track| (!track.is_empty()).then_some(track.as_slice()))
        .collect();
    let positions: Vec<glam::Vec3> = model.means.iter().map(|m| glam::Vec3::from(*m)).collect();
    model.object_ids = vote_object_ids(&positions, &observations, masks, voting);
    // Objects the points missed get points carved from their visual hull, voted like the rest.
    let hull = hull_points_for_missed_objects(masks, &model, HullFill::default(), carved);
    if !hull.is_empty() {
        let first_new = model.len();
        append_points(&mut model, &hull);
        let ids = vote_object_ids(&hull, &vec![None; hull.len()], masks, voting);
        model.object_ids[first_new..].copy_from_slice(&ids);
        tracing::info!(
            points = hull.len(),
            "visual-hull points for objects the sparse points missed"
        );
    }
    // Appended after the vote: the shell never belongs to an object.
    append_points(
        &mut model,
        &background_shell_points(scene, background_shell),
    );
    Ok(model)
}

/// Share of a dynamic scene's time span, from its first time, whose views vote for the initial
/// object ids.
const DYNAMIC_VOTING_TIME_SHARE: f32 = 0.25;
/// Views that vote in a dynamic scene at least (when it has them).
const DYNAMIC_VOTING_MIN_VIEWS: usize = 4;

/// The views whose masks vote for the initial ids. In a static scene, all. In a moving one, an
/// object is somewhere else in every view, so a point would win a majority only in the core its
/// object never leaves; the views of the earliest times vote instead: the deformation field
/// starts as the identity, so the canonical Gaussians begin where the scene is then, and the
/// field carries each object's Gaussians to its other times.
fn voting_views<'a>(scene: &Scene, masks: &'a ViewMaskSet) -> std::borrow::Cow<'a, ViewMaskSet> {
    let time = |view: &super::view_masks::ViewMasks| {
        scene
            .frames
            .get(view.frame_index)
            .and_then(|frame| frame.time)
    };
    let times: Vec<f32> = masks.views.iter().filter_map(time).collect();
    if !scene.is_dynamic() || times.len() < masks.views.len() || times.is_empty() {
        return std::borrow::Cow::Borrowed(masks);
    }
    let first = times.iter().copied().fold(f32::INFINITY, f32::min);
    let last = times.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sorted = times.clone();
    sorted.sort_by(f32::total_cmp);
    let nth = sorted[DYNAMIC_VOTING_MIN_VIEWS.min(sorted.len()) - 1];
    let cutoff = (first + DYNAMIC_VOTING_TIME_SHARE * (last - first)).max(nth);
    let views = masks
        .views
        .iter()
        .filter(|view| time(view).is_some_and(|t| t <= cutoff))
        .cloned()
        .collect();
    std::borrow::Cow::Owned(ViewMaskSet { views })
}

/// Each sparse point's COLMAP track as (index into `masks.views`, full-resolution pixel), keeping
/// only the observations in those views; empty for points without a track.
pub(super) fn point_tracks_in_views(
    points: &SparsePoints,
    masks: &ViewMaskSet,
) -> Vec<Vec<(usize, [f32; 2])>> {
    let view_from_frame = |frame: u32| {
        masks
            .views
            .iter()
            .position(|view| view.frame_index == frame as usize)
    };
    points
        .tracks
        .iter()
        .map(|track| {
            track
                .iter()
                .filter_map(|seen| Some((view_from_frame(seen.frame_index)?, seen.pixel)))
                .collect()
        })
        .collect()
}

/// A trainer for Segment then Splat on `scene` with the user's masks (stage 1 skipped); see
/// [`segmented_trainer_from_view_masks`].
pub fn segmented_trainer_from_user_masks(
    ctx: &GpuContext,
    scene: &Scene,
    config: TrainConfig,
    options: &SegmentedTrainingOptions,
) -> Result<Trainer, SegmentedTrainingError> {
    let frames = training_frames(scene, &config);
    let masks = ViewMaskSet::from_user_masks(scene, &frames, config.max_resolution)?;
    segmented_trainer_from_view_masks(ctx, scene, config, &masks, options, CarvedHulls::default())
}

/// A trainer like [`segmented_trainer_from_user_masks`], with masks made by `generator` on the
/// training views (at the training resolution) and given one id per object across views by
/// their shared sparse points ([`generated_view_masks`]). Also answers what association did.
pub fn segmented_trainer_from_generated_masks(
    ctx: &GpuContext,
    scene: &Scene,
    config: TrainConfig,
    generator: &mut MaskGenerator,
    options: &SegmentedTrainingOptions,
    association: &AssociationOptions,
) -> Result<(Trainer, AssociationReport), SegmentedTrainingError> {
    let frames = training_frames(scene, &config);
    let (mut masks, report) = generated_view_masks(
        scene,
        &frames,
        generator,
        config.max_resolution,
        association,
    )?;
    let (_, carved) = merge_lost_tracks(scene, &mut masks, &config, TrackMergeRule::default())?;
    let trainer = segmented_trainer_from_view_masks(ctx, scene, config, &masks, options, carved)?;
    Ok((trainer, report))
}

/// The trainer for masks of exactly the training views, in training order: ids voted onto the
/// initial Gaussians, the object loss on (its default config unless `config.object_loss` is
/// set), the persistence floor guarding pruning. The hull points `carved` holds from the
/// lost-track merge ([`super::track_merge::merge_lost_tracks`]) are reused where the merge left
/// them valid: the same model, without carving them twice (an empty [`CarvedHulls`] carves all).
pub fn segmented_trainer_from_view_masks(
    ctx: &GpuContext,
    scene: &Scene,
    mut config: TrainConfig,
    masks: &ViewMaskSet,
    options: &SegmentedTrainingOptions,
    mut carved: CarvedHulls,
) -> Result<Trainer, SegmentedTrainingError> {
    config
        .object_loss
        .get_or_insert_with(ObjectLossConfig::default);
    resolve_adapter_sized(&mut config, scene, ctx);
    let model = initial_segmented_model(
        scene,
        masks,
        &config,
        options.voting,
        options.background_shell,
        &mut carved,
    )?;
    tracing::debug!(
        reused = carved.reused(),
        "hull points reused from the lost-track merge"
    );
    let mut trainer = Trainer::new(ctx, scene, config, Some(model))?;
    attach_object_training(ctx, &mut trainer, masks, options)?;
    Ok(trainer)
}

/// Gives a trainer (new or resumed) what the object loss needs beyond its checkpointed state:
/// the training views' masks on the GPU and the persistence floor. `masks` must be of exactly
/// the trainer's training views, in its order.
pub fn attach_object_training(
    ctx: &GpuContext,
    trainer: &mut Trainer,
    masks: &ViewMaskSet,
    options: &SegmentedTrainingOptions,
) -> Result<(), SegmentedTrainingError> {
    for (train_view, (view, view_masks)) in
        trainer.views().train.iter().zip(&masks.views).enumerate()
    {
        if view.frame_index != view_masks.frame_index {
            return Err(SegmentedTrainingError::ViewOrder {
                train_view,
                trainer_frame: view.frame_index,
                mask_frame: view_masks.frame_index,
            });
        }
    }
    trainer.set_prune_guard(Box::new(ObjectFloor {
        floors: options.object_floors,
    }));
    let ids: Vec<ViewIdMaps> = masks
        .views
        .iter()
        .map(|view| ViewIdMaps {
            width: view.camera.width,
            ids: Level::ALL.map(|level| view.ids(level)),
        })
        .collect();
    trainer.set_object_targets(ObjectTargets::upload(ctx, &ids))?;
    Ok(())
}
