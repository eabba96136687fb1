//! User-provided instance-id masks: `masks/{small,middle,large}/<image name>.png`, one PNG per
//! frame, single-channel 8- or 16-bit, 0 = no object.

use std::path::{Path, PathBuf};

use image::DynamicImage;

use super::distortion::undistort_mask;
use super::images::{decode_image, frame_lens, size_mismatch};
use super::{Frame, InstanceMask, Level, MaskLayout, Scene, SceneError};

pub const MASKS_DIR: &str = "masks";

/// The mask path for a frame: its name (relative to the image folder) with a `.png` extension,
/// under `masks/<level>/`.
pub fn mask_path(level: Level, frame_name: &str) -> PathBuf {
    Path::new(MASKS_DIR)
        .join(level.name())
        .join(Path::new(frame_name).with_extension("png"))
}

/// Finds the given levels and checks every frame has a mask file in each; `None` without a
/// `masks/` folder. Masks are not decoded here.
pub fn discover_masks(root: &Path, frames: &[Frame]) -> Result<Option<MaskLayout>, SceneError> {
    let masks_dir = root.join(MASKS_DIR);
    if !masks_dir.is_dir() {
        return Ok(None);
    }
    let mut layout = MaskLayout::default();
    for level in Level::ALL {
        if !masks_dir.join(level.name()).is_dir() {
            continue;
        }
        let paths: Vec<PathBuf> = frames
            .iter()
            .map(|frame| mask_path(level, &frame.name))
            .collect();
        if let Some(missing) = paths.iter().find(|path| !root.join(path).is_file()) {
            return Err(SceneError::Inconsistent {
                file: missing.display().to_string(),
                message: format!(
                    "mask missing: every frame needs a mask in {MASKS_DIR}/{} once that level is given",
                    level.name()
                ),
            });
        }
        layout.paths[level.index()] = Some(paths);
    }
    if layout.given_levels().is_empty() {
        return Err(SceneError::Inconsistent {
            file: MASKS_DIR.to_string(),
            message: "expected sub-folders small, middle and/or large".to_string(),
        });
    }
    Ok(Some(layout))
}

/// The instance mask serving `level` for frame `frame_index` (a missing level falls back as
/// [`MaskLayout::source_level`] says), undistorted like the frame's image when its camera has
/// distortion (nearest pixel, so ids stay ids); `Ok(None)` when the scene has no user masks.
pub fn load_instance_mask(
    scene: &Scene,
    level: Level,
    frame_index: usize,
) -> Result<Option<InstanceMask>, SceneError> {
    let Some(layout) = &scene.masks else {
        return Ok(None);
    };
    let Some(frame) = scene.frames.get(frame_index) else {
        return Err(SceneError::Inconsistent {
            file: scene.root.display().to_string(),
            message: format!(
                "frame {frame_index} requested but the scene has {} frames",
                scene.frames.len()
            ),
        });
    };
    let Some(path) = layout.path_for(level, frame_index) else {
        return Ok(None);
    };
    let mask = decode_mask(&scene.root, path)?;
    let expected = (frame.intrinsics.width, frame.intrinsics.height);
    if (mask.width, mask.height) != expected {
        return Err(size_mismatch(path, (mask.width, mask.height), expected));
    }
    let lens = frame_lens(frame)?;
    if lens.is_pinhole() {
        return Ok(Some(mask));
    }
    Ok(Some(undistort_mask(&mask, &frame.intrinsics, &lens).0))
}

/// Decodes one mask file, refusing anything but single-channel 8- or 16-bit images.
pub(crate) fn decode_mask(root: &Path, relative_path: &Path) -> Result<InstanceMask, SceneError> {
    let decoded = decode_image(root, relative_path)?;
    let (width, height) = (decoded.width(), decoded.height());
    let ids = match decoded {
        DynamicImage::ImageLuma8(gray) => gray.into_raw().into_iter().map(u32::from).collect(),
        DynamicImage::ImageLuma16(gray) => gray.into_raw().into_iter().map(u32::from).collect(),
        other => {
            return Err(SceneError::UndecodableImage {
                file: relative_path.display().to_string(),
                message: format!(
                    "masks must be single-channel 8- or 16-bit instance ids, found {:?}",
                    other.color()
                ),
            });
        }
    };
    Ok(InstanceMask { width, height, ids })
}
