//! Stage 1 by re-prompting, for captures whose views are a sequence rather than posed stills
//! with shared 3D points (docs/method.md stage 1, steps 1-4): automatic masks on the first training
//! view, then every object carried to the next view by prompting the SAM decoder with its
//! previous mask (`segment::propagation`), with new-object checks and duplicate drops every
//! `stride` views. Identity comes from appearance, so neither poses nor sparse points are needed.

use super::association::frame_rgb8;
use super::view_masks::{ViewMaskSet, ViewMaskSetError, ViewMasks};
use segsplat_scene::{Level, Scene, SceneError};
use segsplat_vision::segment::propagation::{
    FirstFrameMasks, PropagationError, PropagationOptions, PropagationReport, propagate_masks,
};
use segsplat_vision::segment::{MaskGenerator, RegionPromptSegmenter, SegmentError};

/// The new-object area rule is stated for a 1000-pixel-wide image, as in `association`.
const REFERENCE_WIDTH: f64 = 1000.0;

#[derive(Debug, thiserror::Error)]
pub enum PropagatedMasksError {
    #[error("no training views to segment")]
    NoViews,
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("automatic masks on the first view: {0}")]
    FirstView(#[from] SegmentError),
    #[error(transparent)]
    Propagation(#[from] PropagationError),
    #[error(transparent)]
    Views(#[from] ViewMaskSetError),
}

/// Masks of `frames` (in this order) at three levels with ids consistent along the sequence.
pub fn propagated_view_masks(
    scene: &Scene,
    frames: &[usize],
    segmenter: &mut dyn RegionPromptSegmenter,
    generator: &mut MaskGenerator,
    max_side: Option<u32>,
    options: &PropagationOptions,
) -> Result<(ViewMaskSet, PropagationReport), PropagatedMasksError> {
    let &first_frame = frames.first().ok_or(PropagatedMasksError::NoViews)?;
    let first_image = frame_rgb8(scene, first_frame, max_side)?;
    let (width, height) = first_image.dimensions();
    let first_masks = generator.generate(&first_image, first_frame)?;
    let first = FirstFrameMasks {
        width,
        height,
        ids: Level::ALL.map(|level| first_masks.instance_ids(level, width, height)),
    };
    let options = PropagationOptions {
        full_resolution_scale: f64::from(width) / REFERENCE_WIDTH,
        ..options.clone()
    };
    let propagation = propagate_masks(
        frames.len(),
        |position| frame_rgb8(scene, frames[position], max_side),
        first,
        segmenter,
        generator,
        &options,
    )?;
    let views = frames
        .iter()
        .zip(propagation.frames)
        .map(|(&frame_index, ids)| {
            ViewMasks::without_objects(scene, frame_index, max_side)?.with_level_ids(ids)
        })
        .collect::<Result<Vec<_>, ViewMaskSetError>>()?;
    Ok((ViewMaskSet { views }, propagation.report))
}
