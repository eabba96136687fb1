//! Blender NeRF datasets (the NeRF "synthetic" layout, also D-NeRF): `transforms_train.json`,
//! optional `transforms_val.json` and `transforms_test.json`, one horizontal field of view for
//! all frames, OpenGL camera-to-world poses, RGBA images (composited on the background when
//! decoded) whose `file_path` often lacks the `.png` extension.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::images::image_size;
use super::transforms_json::{opencv_world_from_camera, read_json, relative_file_path};
use super::{Frame, FrameSplit, Intrinsics, LoadOptions, Scene, SceneError, SceneFormat};

pub const TRAIN_TRANSFORMS_FILE: &str = "transforms_train.json";
pub const VAL_TRANSFORMS_FILE: &str = "transforms_val.json";
pub const TEST_TRANSFORMS_FILE: &str = "transforms_test.json";

#[derive(Debug, Deserialize)]
struct TransformsFile {
    camera_angle_x: f64,
    camera_angle_y: Option<f64>,
    frames: Vec<FrameEntry>,
}

#[derive(Debug, Deserialize)]
struct FrameEntry {
    file_path: String,
    transform_matrix: Vec<Vec<f64>>,
    /// D-NeRF capture time, normalised to 0..1 by the dataset itself.
    time: Option<f32>,
}

/// Frames come in split order (train, val, test), each in file order. The field of view is the
/// train file's; every split shares it, as in the NeRF synthetic data.
pub fn load_blender(root: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let train: TransformsFile = read_json(root, TRAIN_TRANSFORMS_FILE)?;
    let Some(first_entry) = train.frames.first() else {
        return Err(SceneError::Inconsistent {
            file: TRAIN_TRANSFORMS_FILE.to_string(),
            message: "frames is empty".to_string(),
        });
    };
    let first_image = image_path(root, &first_entry.file_path, TRAIN_TRANSFORMS_FILE, 0)?;
    let intrinsics = intrinsics_from_first_image(
        root,
        &first_image,
        train.camera_angle_x,
        train.camera_angle_y,
    )?;
    let mut frames = Vec::new();
    append_frames(
        root,
        &train,
        TRAIN_TRANSFORMS_FILE,
        FrameSplit::Train,
        &intrinsics,
        &mut frames,
    )?;
    for (file, split) in [
        (VAL_TRANSFORMS_FILE, FrameSplit::Val),
        (TEST_TRANSFORMS_FILE, FrameSplit::Test),
    ] {
        if root.join(file).is_file() {
            let transforms: TransformsFile = read_json(root, file)?;
            append_frames(root, &transforms, file, split, &intrinsics, &mut frames)?;
        }
    }
    Ok(Scene {
        root: root.to_path_buf(),
        format: SceneFormat::Blender,
        frames,
        points: None,
        masks: None,
        background: options.background,
    })
}

fn append_frames(
    root: &Path,
    transforms: &TransformsFile,
    file: &str,
    split: FrameSplit,
    intrinsics: &Intrinsics,
    frames: &mut Vec<Frame>,
) -> Result<(), SceneError> {
    for (frame_index, entry) in transforms.frames.iter().enumerate() {
        let image_path = image_path(root, &entry.file_path, file, frame_index)?;
        // D-NeRF times are already normalised; anything else would break that promise.
        if let Some(time) = entry.time
            && !(0.0..=1.0).contains(&time)
        {
            return Err(SceneError::Parse {
                file: file.to_string(),
                message: format!("frame {frame_index}: time {time} is outside 0..1"),
            });
        }
        frames.push(Frame {
            name: slash_separated(&image_path),
            image_path,
            intrinsics: intrinsics.clone(),
            world_from_camera: opencv_world_from_camera(
                &entry.transform_matrix,
                file,
                frame_index,
            )?,
            time: entry.time,
            source_id: None,
            split: Some(split),
        });
    }
    Ok(())
}

/// The image file for a `file_path`: as given when it exists, else with `.png` appended
/// (Blender files usually omit it); when neither exists the `.png` form is reported missing
/// later, unless the path already had an extension.
fn image_path(
    root: &Path,
    file_path: &str,
    file: &str,
    frame_index: usize,
) -> Result<PathBuf, SceneError> {
    let given = relative_file_path(file_path, file, frame_index)?;
    let mut with_png = given.clone().into_os_string();
    with_png.push(".png");
    let with_png = PathBuf::from(with_png);
    if root.join(&given).is_file() {
        Ok(given)
    } else if root.join(&with_png).is_file() || given.extension().is_none() {
        Ok(with_png)
    } else {
        Ok(given)
    }
}

fn slash_separated(path: &Path) -> String {
    path.components()
        .map(|component| component.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}

/// Blender datasets give no image size: it is read from the first image's header, and every
/// frame is checked against it during validation.
fn intrinsics_from_first_image(
    root: &Path,
    first_image: &Path,
    angle_x: f64,
    angle_y: Option<f64>,
) -> Result<Intrinsics, SceneError> {
    let (width, height) = image_size(root, first_image)?;
    if !(angle_x > 0.0 && angle_x < std::f64::consts::PI) {
        return Err(SceneError::Parse {
            file: TRAIN_TRANSFORMS_FILE.to_string(),
            message: format!("camera_angle_x = {angle_x} is not an angle in (0, pi) radians"),
        });
    }
    let fx = 0.5 * f64::from(width) / (0.5 * angle_x).tan();
    let fy = match angle_y {
        Some(angle_y) if angle_y > 0.0 && angle_y < std::f64::consts::PI => {
            0.5 * f64::from(height) / (0.5 * angle_y).tan()
        }
        _ => fx,
    };
    Ok(Intrinsics {
        width,
        height,
        fx,
        fy,
        cx: f64::from(width) / 2.0,
        cy: f64::from(height) / 2.0,
        model: "PINHOLE".to_string(),
        distortion: Vec::new(),
    })
}
