//! Full validation of a parsed scene: every image and mask decoded and checked against its
//! camera. Images are decoded in parallel; the first error in frame order is reported.

use rayon::prelude::*;

use super::images::{decoded_size, size_mismatch};
use super::masks::decode_mask;
use super::pixel_limits::{PixelLimits, check_pixel_limits};
use super::{Scene, SceneError, SceneSummary};

/// Decodes every referenced image and mask and checks sizes and counts; returns the summary the
/// upload endpoint replies with. Images are bounded by [`PixelLimits::default`].
pub fn validate_scene(scene: &Scene) -> Result<SceneSummary, SceneError> {
    validate_scene_within(scene, &PixelLimits::default())
}

/// [`validate_scene`] with these bounds on image size, checked from the headers before any
/// image is decoded.
pub fn validate_scene_within(
    scene: &Scene,
    limits: &PixelLimits,
) -> Result<SceneSummary, SceneError> {
    if scene.frames.is_empty() {
        return Err(SceneError::Inconsistent {
            file: scene.root.display().to_string(),
            message: "the dataset has no frames".to_string(),
        });
    }
    check_points(scene)?;
    check_pixel_limits(scene, limits)?;
    scene
        .frames
        .par_iter()
        .enumerate()
        .map(|(frame_index, frame)| {
            let expected = (frame.intrinsics.width, frame.intrinsics.height);
            let actual = decoded_size(&scene.root, &frame.image_path)?;
            if actual != expected {
                return Err(size_mismatch(&frame.image_path, actual, expected));
            }
            let mask_paths = scene.masks.iter().flat_map(|layout| {
                layout
                    .paths
                    .iter()
                    .flatten()
                    .filter_map(move |paths| paths.get(frame_index))
            });
            for mask_path in mask_paths {
                let mask = decode_mask(&scene.root, mask_path)?;
                if (mask.width, mask.height) != expected {
                    return Err(size_mismatch(
                        mask_path,
                        (mask.width, mask.height),
                        expected,
                    ));
                }
            }
            Ok(())
        })
        .collect::<Vec<Result<(), SceneError>>>()
        .into_iter()
        .collect::<Result<Vec<()>, SceneError>>()?;

    let mut resolutions: Vec<[u32; 2]> = scene
        .frames
        .iter()
        .map(|frame| [frame.intrinsics.width, frame.intrinsics.height])
        .collect();
    resolutions.sort_unstable();
    resolutions.dedup();
    Ok(SceneSummary {
        format: scene.format,
        frame_count: scene.frames.len() as u32,
        resolutions,
        sparse_point_count: scene
            .points
            .as_ref()
            .map_or(0, |points| points.positions.len() as u64),
        mask_levels: scene
            .masks
            .as_ref()
            .map(|layout| layout.given_levels())
            .unwrap_or_default(),
        time_count: scene.frame_times().len() as u32,
        ignored_file_count: 0,
        ignored_files: Vec::new(),
        undistorted: crate::distortion::undistorted_lenses(scene),
    })
}

fn check_points(scene: &Scene) -> Result<(), SceneError> {
    let Some(points) = &scene.points else {
        return Ok(());
    };
    let count = points.positions.len();
    let inconsistent = |message: String| SceneError::Inconsistent {
        file: "sparse points".to_string(),
        message,
    };
    if points.colors.len() != count || points.tracks.len() != count {
        return Err(inconsistent(format!(
            "{count} positions but {} colours and {} tracks",
            points.colors.len(),
            points.tracks.len()
        )));
    }
    let frame_count = scene.frames.len();
    let bad_observation = points
        .tracks
        .iter()
        .flatten()
        .find(|observation| observation.frame_index as usize >= frame_count);
    if let Some(observation) = bad_observation {
        return Err(inconsistent(format!(
            "a track names frame {} but there are {frame_count} frames",
            observation.frame_index
        )));
    }
    Ok(())
}
