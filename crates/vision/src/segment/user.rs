//! User-provided masks (`masks/{small,middle,large}/<frame>.png` instance-id images, see
//! docs/scene.md) as the same per-level output as generated masks, so they bypass segmentation.

use super::mask::{BitMask, MaskError};
use super::scored::{FrameMasks, ScoredMask};
use segsplat_scene::{InstanceMask, Level, Scene, SceneError, load_instance_mask};

/// Why user masks could not be used.
#[derive(Debug, thiserror::Error)]
pub enum UserMaskError {
    #[error("the scene has no user masks (masks/small, masks/middle or masks/large)")]
    NoUserMasks,
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("instance mask: {0}")]
    Mask(#[from] MaskError),
}

/// One mask per non-zero instance id, in increasing id order, each keeping its id.
pub fn masks_from_instance_image(
    instance_mask: &InstanceMask,
) -> Result<Vec<ScoredMask>, UserMaskError> {
    let masks = BitMask::all_from_instance_ids(
        instance_mask.width,
        instance_mask.height,
        &instance_mask.ids,
    )?;
    Ok(masks
        .into_iter()
        .filter_map(|(id, mask)| ScoredMask::certain(mask, Some(id)))
        .collect())
}

/// The user masks of one frame at all three levels (a level the user did not give falls back as
/// `MaskLayout::source_level` says).
pub fn user_frame_masks(scene: &Scene, frame_index: usize) -> Result<FrameMasks, UserMaskError> {
    let mut frame = FrameMasks::default();
    for level in Level::ALL {
        let instance_mask =
            load_instance_mask(scene, level, frame_index)?.ok_or(UserMaskError::NoUserMasks)?;
        frame.levels[level.index()] = masks_from_instance_image(&instance_mask)?;
    }
    Ok(frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_instance_becomes_a_certain_mask_with_its_id() {
        let instance_mask = InstanceMask {
            width: 4,
            height: 2,
            ids: vec![0, 9, 9, 0, 300, 300, 9, 0],
        };
        let masks = masks_from_instance_image(&instance_mask).expect("consistent");
        assert_eq!(masks.len(), 2);
        assert_eq!(masks[0].instance_id, Some(9));
        assert_eq!(masks[0].area, 3);
        assert_eq!(masks[1].instance_id, Some(300));
        assert_eq!(masks[1].bbox.to_xywh(), [0, 1, 2, 1]);
        assert_eq!(masks[1].score, 1.0);
        let broken = InstanceMask {
            width: 4,
            height: 3,
            ids: vec![0; 8],
        };
        assert!(matches!(
            masks_from_instance_image(&broken),
            Err(UserMaskError::Mask(MaskError::LengthMismatch { .. }))
        ));
    }
}
