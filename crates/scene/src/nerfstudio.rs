//! nerfstudio datasets: `transforms.json` with intrinsics given globally or per frame and
//! camera-to-world poses in the OpenGL convention. The optional `ply_file_path` point cloud
//! (in the same world frame as the poses) becomes the scene's sparse points, without tracks.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::dataset_path::contained_relative_path;
use super::distortion::Lens;
use super::point_ply::read_point_ply;
use super::transforms_json::{opencv_world_from_camera, read_json, relative_file_path};
use super::{Frame, Intrinsics, LoadOptions, Scene, SceneError, SceneFormat};

pub const TRANSFORMS_FILE: &str = "transforms.json";

/// The image folder prefix stripped from `file_path` to form a frame name.
const IMAGES_PREFIX: &str = "images";

/// Intrinsic fields that may appear at the top level or in a frame (frame values win).
#[derive(Debug, Clone, Default, Deserialize)]
struct CameraFields {
    camera_model: Option<String>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    k4: Option<f64>,
    k5: Option<f64>,
    k6: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
}

impl CameraFields {
    fn overridden_by(&self, frame: &CameraFields) -> CameraFields {
        CameraFields {
            camera_model: frame
                .camera_model
                .clone()
                .or_else(|| self.camera_model.clone()),
            fl_x: frame.fl_x.or(self.fl_x),
            fl_y: frame.fl_y.or(self.fl_y),
            cx: frame.cx.or(self.cx),
            cy: frame.cy.or(self.cy),
            w: frame.w.or(self.w),
            h: frame.h.or(self.h),
            k1: frame.k1.or(self.k1),
            k2: frame.k2.or(self.k2),
            k3: frame.k3.or(self.k3),
            k4: frame.k4.or(self.k4),
            k5: frame.k5.or(self.k5),
            k6: frame.k6.or(self.k6),
            p1: frame.p1.or(self.p1),
            p2: frame.p2.or(self.p2),
        }
    }
}

#[derive(Debug, Deserialize)]
struct TransformsFile {
    #[serde(flatten)]
    camera: CameraFields,
    frames: Vec<FrameEntry>,
    ply_file_path: Option<String>,
}

#[derive(Debug, Deserialize)]
struct FrameEntry {
    file_path: String,
    transform_matrix: Vec<Vec<f64>>,
    #[serde(flatten)]
    camera: CameraFields,
}

pub fn load_nerfstudio(root: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let transforms: TransformsFile = read_json(root, TRANSFORMS_FILE)?;
    if transforms.frames.is_empty() {
        return Err(SceneError::Inconsistent {
            file: TRANSFORMS_FILE.to_string(),
            message: "frames is empty".to_string(),
        });
    }
    let mut frames = Vec::with_capacity(transforms.frames.len());
    for (frame_index, entry) in transforms.frames.iter().enumerate() {
        let image_path = relative_file_path(&entry.file_path, TRANSFORMS_FILE, frame_index)?;
        let camera = transforms.camera.overridden_by(&entry.camera);
        frames.push(Frame {
            name: frame_name(&image_path),
            intrinsics: intrinsics(&camera, frame_index)?,
            world_from_camera: opencv_world_from_camera(
                &entry.transform_matrix,
                TRANSFORMS_FILE,
                frame_index,
            )?,
            image_path,
            time: None,
            source_id: None,
            split: None,
        });
    }
    frames.sort_by(|a, b| a.name.cmp(&b.name));
    if let Some(pair) = frames.windows(2).find(|pair| pair[0].name == pair[1].name) {
        return Err(SceneError::Parse {
            file: TRANSFORMS_FILE.to_string(),
            message: format!("image {} is listed twice", pair[0].name),
        });
    }
    let points = match &transforms.ply_file_path {
        Some(ply_file_path) => {
            let relative =
                contained_relative_path(ply_file_path).ok_or_else(|| SceneError::Parse {
                    file: TRANSFORMS_FILE.to_string(),
                    message: format!(
                        "ply_file_path {ply_file_path:?} must be a path inside the dataset"
                    ),
                })?;
            Some(read_point_ply(root, &relative)?)
        }
        None => None,
    };
    Ok(Scene {
        root: root.to_path_buf(),
        format: SceneFormat::Nerfstudio,
        frames,
        points,
        masks: None,
        background: options.background,
    })
}

/// The path with a leading `images/` folder removed, as a `/`-separated string.
fn frame_name(image_path: &Path) -> String {
    let stripped: PathBuf = match image_path.strip_prefix(IMAGES_PREFIX) {
        Ok(rest) if !rest.as_os_str().is_empty() => rest.to_path_buf(),
        _ => image_path.to_path_buf(),
    };
    stripped
        .components()
        .map(|component| component.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}

fn intrinsics(camera: &CameraFields, frame_index: usize) -> Result<Intrinsics, SceneError> {
    let missing = |field: &str| SceneError::Parse {
        file: TRANSFORMS_FILE.to_string(),
        message: format!("frame {frame_index}: {field} is missing (neither global nor per frame)"),
    };
    let side = |value: Option<f64>, field: &str| -> Result<u32, SceneError> {
        let value = value.ok_or_else(|| missing(field))?;
        if value.fract() != 0.0 || value < 1.0 || value > f64::from(u32::MAX) {
            return Err(SceneError::Parse {
                file: TRANSFORMS_FILE.to_string(),
                message: format!("frame {frame_index}: {field} = {value} is not a pixel count"),
            });
        }
        Ok(value as u32)
    };
    let width = side(camera.w, "w")?;
    let height = side(camera.h, "h")?;
    let fx = camera.fl_x.ok_or_else(|| missing("fl_x"))?;
    let fy = camera.fl_y.unwrap_or(fx);
    let cx = camera.cx.unwrap_or(f64::from(width) / 2.0);
    let cy = camera.cy.unwrap_or(f64::from(height) / 2.0);
    let (model, distortion) = distortion(camera, frame_index)?;
    let intrinsics = Intrinsics {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        model,
        distortion,
    };
    Lens::from_intrinsics(&intrinsics).map_err(|message| SceneError::Parse {
        file: TRANSFORMS_FILE.to_string(),
        message: format!("frame {frame_index}: {message}"),
    })?;
    Ok(intrinsics)
}

/// `camera_model` values nerfstudio reads as a perspective camera with OpenCV distortion.
const PERSPECTIVE_MODELS: [&str; 5] = [
    "OPENCV",
    "PINHOLE",
    "SIMPLE_PINHOLE",
    "SIMPLE_RADIAL",
    "RADIAL",
];

/// nerfstudio's distortion fields in the parameter order of the matching COLMAP model:
/// OPENCV_FISHEYE `k1..k4`; the perspective models (no `camera_model`, OPENCV, PINHOLE,
/// SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL, which nerfstudio all treats as OPENCV) `k1 k2 p1 p2`,
/// or FULL_OPENCV `k1 k2 p1 p2 k3 k4 k5 k6` when `k3`..`k6` are set. nerfstudio's own converter
/// writes those from COLMAP's FULL_OPENCV cameras, so `k4`..`k6` are read as COLMAP's rational
/// denominator terms. Other models are refused, naming the model.
fn distortion(camera: &CameraFields, frame_index: usize) -> Result<(String, Vec<f64>), SceneError> {
    let value = |field: Option<f64>| field.unwrap_or(0.0);
    let (k1, k2, k3, k4) = (
        value(camera.k1),
        value(camera.k2),
        value(camera.k3),
        value(camera.k4),
    );
    let (k5, k6) = (value(camera.k5), value(camera.k6));
    let (p1, p2) = (value(camera.p1), value(camera.p2));
    match camera.camera_model.as_deref() {
        Some("OPENCV_FISHEYE") => {
            if [p1, p2, k5, k6].iter().any(|k| *k != 0.0) {
                tracing::warn!(
                    frame_index,
                    "{TRANSFORMS_FILE}: OPENCV_FISHEYE uses k1..k4; p1, p2, k5 and k6 are ignored"
                );
            }
            Ok(("OPENCV_FISHEYE".to_string(), vec![k1, k2, k3, k4]))
        }
        Some(other) if !PERSPECTIVE_MODELS.contains(&other) => Err(SceneError::Parse {
            file: TRANSFORMS_FILE.to_string(),
            message: format!(
                "frame {frame_index}: camera_model {other:?} is not supported (supported: \
                 OPENCV, OPENCV_FISHEYE, PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL)"
            ),
        }),
        declared => {
            if [k3, k4, k5, k6].iter().any(|k| *k != 0.0) {
                Ok((
                    "FULL_OPENCV".to_string(),
                    vec![k1, k2, p1, p2, k3, k4, k5, k6],
                ))
            } else if declared == Some("OPENCV") || [k1, k2, p1, p2].iter().any(|k| *k != 0.0) {
                Ok(("OPENCV".to_string(), vec![k1, k2, p1, p2]))
            } else {
                Ok(("PINHOLE".to_string(), Vec::new()))
            }
        }
    }
}
