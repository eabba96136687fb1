//! Blender NeRF datasets (the NeRF "synthetic" layout, also D-NeRF): `transforms_train.json`,
//! optional `transforms_val.json` and `transforms_test.json`, one horizontal field of view for
//! all frames, OpenGL camera-to-world poses, RGBA images (composited on the background when
//! decoded) whose `file_path` often lacks the `.png` extension.

use std::path::{Path, PathBuf};

use serde::Deserialize;

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
    /// D-NeRF capture time (0..1).
    time: Option<f32>,
}

/// Frames come in split order (train, val, test), each in file order.
pub fn load_blender(root: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let mut frames = Vec::new();
    let mut field_of_view = None;
    let splits = [
        (TRAIN_TRANSFORMS_FILE, FrameSplit::Train),
        (VAL_TRANSFORMS_FILE, FrameSplit::Val),
        (TEST_TRANSFORMS_FILE, FrameSplit::Test),
    ];
    for (file, split) in splits {
        if split != FrameSplit::Train && !root.join(file).is_file() {
            continue;
        }
        let transforms: TransformsFile = read_json(root, file)?;
        field_of_view.get_or_insert((transforms.camera_angle_x, transforms.camera_angle_y));
        for (frame_index, entry) in transforms.frames.iter().enumerate() {
            let image_path = image_path(root, &entry.file_path, file, frame_index)?;
            frames.push(Frame {
                name: slash_separated(&image_path),
                image_path,
                // Filled in below once the image size is known.
                intrinsics: Intrinsics {
                    width: 0,
                    height: 0,
                    fx: 0.0,
                    fy: 0.0,
                    cx: 0.0,
                    cy: 0.0,
                    model: "PINHOLE".to_string(),
                    distortion: Vec::new(),
                },
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
    }
    let Some(first) = frames.first() else {
        return Err(SceneError::Inconsistent {
            file: TRAIN_TRANSFORMS_FILE.to_string(),
            message: "frames is empty".to_string(),
        });
    };
    let (angle_x, angle_y) = field_of_view.unwrap_or_default();
    let intrinsics = intrinsics_from_first_image(root, &first.image_path, angle_x, angle_y)?;
    for frame in &mut frames {
        frame.intrinsics = intrinsics.clone();
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
    let file = first_image.display().to_string();
    let full_path = root.join(first_image);
    if !full_path.is_file() {
        return Err(SceneError::MissingImage { file });
    }
    let (width, height) =
        image::image_dimensions(&full_path).map_err(|error| SceneError::UndecodableImage {
            file,
            message: error.to_string(),
        })?;
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
