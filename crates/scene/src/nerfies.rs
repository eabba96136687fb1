//! Nerfies and HyperNeRF captures:
//!
//! ```text
//! dataset.json        { "ids": [...], "train_ids": [...], "val_ids": [...] }
//! metadata.json       { "<id>": { "time_id": 0, "warp_id": 0, ... }, ... }
//! scene.json          { "center": [x, y, z], "scale": s, "near": n, "far": f }   (optional)
//! camera/<id>.json    one camera per frame, at full resolution
//! rgb/<scale>x/<id>.png
//! points.npy          optional float32/float64 (N, 3) points
//! ```
//!
//! A camera's `orientation` is the world-to-camera rotation (its rows are the camera axes in
//! world coordinates) and `position` its centre; the camera frame is OpenCV's (x right, y down,
//! z forward), so no axis flip is needed. Positions and points are normalised with `scene.json`
//! as `(p - center) * scale`, as Nerfies itself and Deformable-3DGS do.

use std::collections::{HashMap, HashSet};
use std::fs;
use std::path::Path;

use glam::{Mat3, Mat4, Vec3};
use serde::Deserialize;

use super::dataset_path::contained_relative_path;
use super::images::image_size;
use super::npy::read_float_matrix;
use super::transforms_json::read_json;
use super::{
    Frame, FrameSplit, Intrinsics, LoadOptions, Scene, SceneError, SceneFormat, SparsePoints,
};

pub const DATASET_FILE: &str = "dataset.json";
pub const CAMERA_DIR: &str = "camera";
const METADATA_FILE: &str = "metadata.json";
const SCENE_FILE: &str = "scene.json";
const POINTS_FILE: &str = "points.npy";
/// The dataset-level files besides the cameras (what an upload stores of them).
pub const METADATA_FILES: [&str; 4] = [DATASET_FILE, METADATA_FILE, SCENE_FILE, POINTS_FILE];
const RGB_DIR: &str = "rgb";

/// Nerfies points carry no colour; grey keeps their initial Gaussians neutral.
const POINT_GREY: f32 = 0.5;

/// Whether `root` looks like a Nerfies/HyperNeRF capture.
pub fn is_nerfies(root: &Path) -> bool {
    root.join(DATASET_FILE).is_file() && root.join(CAMERA_DIR).is_dir()
}

#[derive(Debug, Deserialize)]
struct DatasetFile {
    #[serde(default)]
    ids: Vec<String>,
    #[serde(default)]
    train_ids: Vec<String>,
    #[serde(default)]
    val_ids: Vec<String>,
}

#[derive(Debug, Deserialize)]
struct FrameMetadata {
    time_id: Option<f64>,
    warp_id: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct SceneFile {
    center: [f64; 3],
    scale: f64,
}

#[derive(Debug, Deserialize)]
struct CameraFile {
    orientation: [[f64; 3]; 3],
    position: [f64; 3],
    focal_length: f64,
    principal_point: [f64; 2],
    #[serde(default = "one")]
    pixel_aspect_ratio: f64,
    #[serde(default)]
    skew: f64,
    #[serde(default)]
    radial_distortion: Vec<f64>,
    #[serde(default)]
    tangential_distortion: Vec<f64>,
    image_size: [f64; 2],
}

fn one() -> f64 {
    1.0
}

/// `(p - center) * scale`, from `scene.json`; the identity when the file is absent.
#[derive(Debug, Clone, Copy)]
struct Normalisation {
    center: Vec3,
    scale: f32,
}

impl Normalisation {
    fn apply(&self, point: Vec3) -> Vec3 {
        (point - self.center) * self.scale
    }
}

pub fn load_nerfies(root: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let dataset: DatasetFile = read_json(root, DATASET_FILE)?;
    let ids = frame_ids(&dataset)?;
    let metadata: HashMap<String, FrameMetadata> = read_json(root, METADATA_FILE)?;
    let times = normalised_times(&ids, &metadata)?;
    let normalisation = read_normalisation(root)?;
    let scale = image_scale(root, options.nerfies_scale)?;
    let image_dir = Path::new(RGB_DIR).join(format!("{scale}x"));
    let train: HashSet<&str> = dataset.train_ids.iter().map(String::as_str).collect();
    let val: HashSet<&str> = dataset.val_ids.iter().map(String::as_str).collect();

    let mut frames = Vec::with_capacity(ids.len());
    for (id, time) in ids.iter().zip(times) {
        let camera_file = format!("{CAMERA_DIR}/{id}.json");
        let camera: CameraFile = read_json(root, &camera_file)?;
        let name = format!("{id}.png");
        let image_path = image_dir.join(&name);
        let full_resolution = intrinsics(&camera, &camera_file)?;
        let split = if val.contains(id.as_str()) {
            Some(FrameSplit::Val)
        } else if train.contains(id.as_str()) {
            Some(FrameSplit::Train)
        } else {
            None
        };
        frames.push(Frame {
            intrinsics: downscaled_intrinsics(root, &image_path, &full_resolution, scale)?,
            world_from_camera: world_from_camera(&camera, normalisation, &camera_file)?,
            name,
            image_path,
            time: Some(time),
            source_id: None,
            split,
        });
    }
    let points = if root.join(POINTS_FILE).is_file() {
        Some(read_points(root, normalisation)?)
    } else {
        None
    };
    Ok(Scene {
        root: root.to_path_buf(),
        format: SceneFormat::Nerfies,
        frames,
        points,
        masks: None,
        background: options.background,
    })
}

/// `ids` in order, or the train then val ids when `ids` is absent; each id must be a plain file
/// stem (it names files) and appear once.
fn frame_ids(dataset: &DatasetFile) -> Result<Vec<String>, SceneError> {
    let parse_error = |message: String| SceneError::Parse {
        file: DATASET_FILE.to_string(),
        message,
    };
    let ids: Vec<String> = if dataset.ids.is_empty() {
        dataset
            .train_ids
            .iter()
            .chain(&dataset.val_ids)
            .cloned()
            .collect()
    } else {
        dataset.ids.clone()
    };
    if ids.is_empty() {
        return Err(SceneError::Inconsistent {
            file: DATASET_FILE.to_string(),
            message: "ids, train_ids and val_ids are all empty".to_string(),
        });
    }
    let mut seen = HashSet::new();
    for id in &ids {
        let single_component = contained_relative_path(id)
            .is_some_and(|path| path.components().count() == 1 && !id.contains('\\'));
        if !single_component {
            return Err(parse_error(format!(
                "id {id:?} must be a plain file name (it names camera/<id>.json and the image)"
            )));
        }
        if !seen.insert(id.as_str()) {
            return Err(parse_error(format!("id {id:?} is listed twice")));
        }
    }
    Ok(ids)
}

/// Per id, `time_id` (else `warp_id`) over the largest one among the frames, so times span
/// [0, 1] as Deformable-3DGS normalises them; all 0 when every frame has time 0.
fn normalised_times(
    ids: &[String],
    metadata: &HashMap<String, FrameMetadata>,
) -> Result<Vec<f32>, SceneError> {
    let parse_error = |message: String| SceneError::Parse {
        file: METADATA_FILE.to_string(),
        message,
    };
    let mut raw = Vec::with_capacity(ids.len());
    for id in ids {
        let entry = metadata
            .get(id)
            .ok_or_else(|| parse_error(format!("no entry for frame {id:?}")))?;
        let time = entry
            .time_id
            .or(entry.warp_id)
            .ok_or_else(|| parse_error(format!("frame {id:?} has neither time_id nor warp_id")))?;
        if !time.is_finite() || time < 0.0 {
            return Err(parse_error(format!(
                "frame {id:?}: time {time} is not a non-negative number"
            )));
        }
        raw.push(time);
    }
    let largest = raw.iter().copied().fold(0.0, f64::max);
    Ok(raw
        .into_iter()
        .map(|time| {
            if largest > 0.0 {
                (time / largest) as f32
            } else {
                0.0
            }
        })
        .collect())
}

fn read_normalisation(root: &Path) -> Result<Normalisation, SceneError> {
    if !root.join(SCENE_FILE).is_file() {
        return Ok(Normalisation {
            center: Vec3::ZERO,
            scale: 1.0,
        });
    }
    let scene: SceneFile = read_json(root, SCENE_FILE)?;
    let finite = scene.center.iter().all(|value| value.is_finite());
    if !(finite && scene.scale.is_finite() && scene.scale > 0.0) {
        return Err(SceneError::Parse {
            file: SCENE_FILE.to_string(),
            message: "center must be finite and scale a positive number".to_string(),
        });
    }
    Ok(Normalisation {
        center: Vec3::from(scene.center.map(|value| value as f32)),
        scale: scene.scale as f32,
    })
}

/// The requested `rgb/<scale>x` folder, or the smallest scale present.
fn image_scale(root: &Path, requested: Option<u32>) -> Result<u32, SceneError> {
    let rgb_dir = root.join(RGB_DIR);
    let entries = fs::read_dir(&rgb_dir).map_err(|_| SceneError::Inconsistent {
        file: RGB_DIR.to_string(),
        message: "missing: images must be in rgb/<scale>x/ (e.g. rgb/1x/, rgb/2x/)".to_string(),
    })?;
    let mut scales: Vec<u32> = entries
        .filter_map(|entry| entry.ok())
        .filter(|entry| entry.path().is_dir())
        .filter_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            name.strip_suffix('x')?.parse::<u32>().ok()
        })
        .filter(|scale| *scale > 0)
        .collect();
    scales.sort_unstable();
    match requested {
        Some(scale) if scales.contains(&scale) => Ok(scale),
        Some(scale) => Err(SceneError::Inconsistent {
            file: format!("{RGB_DIR}/{scale}x"),
            message: format!("requested image scale is missing; present: {scales:?}"),
        }),
        None => scales
            .first()
            .copied()
            .ok_or_else(|| SceneError::Inconsistent {
                file: RGB_DIR.to_string(),
                message: "holds no <scale>x folder (e.g. 1x, 2x)".to_string(),
            }),
    }
}

/// Full-resolution intrinsics as the camera file gives them; `fy` is the focal length times
/// the pixel aspect ratio, as Nerfies projects. Radial (k1, k2, k3) and tangential (p1, p2)
/// distortion become COLMAP's OPENCV or FULL_OPENCV parameters.
fn intrinsics(camera: &CameraFile, file: &str) -> Result<Intrinsics, SceneError> {
    let parse_error = |message: String| SceneError::Parse {
        file: file.to_string(),
        message,
    };
    let [width, height] = camera.image_size;
    let side_ok = |side: f64| side.fract() == 0.0 && side >= 1.0 && side <= f64::from(u32::MAX);
    if !side_ok(width) || !side_ok(height) {
        return Err(parse_error(format!(
            "image_size {:?} is not a pixel size",
            camera.image_size
        )));
    }
    let scalars = [
        camera.focal_length,
        camera.pixel_aspect_ratio,
        camera.principal_point[0],
        camera.principal_point[1],
        camera.skew,
    ];
    if scalars.iter().any(|value| !value.is_finite())
        || camera.focal_length <= 0.0
        || camera.pixel_aspect_ratio <= 0.0
    {
        return Err(parse_error(
            "focal_length and pixel_aspect_ratio must be positive, all values finite".to_string(),
        ));
    }
    if camera.skew != 0.0 {
        tracing::warn!(
            file,
            skew = camera.skew,
            "camera skew is ignored (pinhole renderer)"
        );
    }
    let coefficient = |values: &[f64], index: usize| values.get(index).copied().unwrap_or(0.0);
    let radial = &camera.radial_distortion;
    let tangential = &camera.tangential_distortion;
    let (k1, k2, k3) = (
        coefficient(radial, 0),
        coefficient(radial, 1),
        coefficient(radial, 2),
    );
    let (p1, p2) = (coefficient(tangential, 0), coefficient(tangential, 1));
    let (model, distortion) = if k3 != 0.0 {
        ("FULL_OPENCV", vec![k1, k2, p1, p2, k3, 0.0, 0.0, 0.0])
    } else if [k1, k2, p1, p2].iter().any(|value| *value != 0.0) {
        ("OPENCV", vec![k1, k2, p1, p2])
    } else {
        ("PINHOLE", Vec::new())
    };
    Ok(Intrinsics {
        width: width as u32,
        height: height as u32,
        fx: camera.focal_length,
        fy: camera.focal_length * camera.pixel_aspect_ratio,
        cx: camera.principal_point[0],
        cy: camera.principal_point[1],
        model: model.to_string(),
        distortion,
    })
}

/// The camera resized to the image actually in the scale folder (read from its header): the
/// downscaled images may round or floor their sides, so the real size decides, as long as it
/// is within a pixel of full size / scale.
fn downscaled_intrinsics(
    root: &Path,
    image_path: &Path,
    full_resolution: &Intrinsics,
    scale: u32,
) -> Result<Intrinsics, SceneError> {
    let (width, height) = image_size(root, image_path)?;
    let expected_width = f64::from(full_resolution.width) / f64::from(scale);
    let expected_height = f64::from(full_resolution.height) / f64::from(scale);
    if (f64::from(width) - expected_width).abs() > 1.0
        || (f64::from(height) - expected_height).abs() > 1.0
    {
        return Err(SceneError::Inconsistent {
            file: image_path.display().to_string(),
            message: format!(
                "image is {width}x{height} but its camera ({}x{}) at scale 1/{scale} says about {expected_width:.0}x{expected_height:.0}",
                full_resolution.width, full_resolution.height
            ),
        });
    }
    Ok(full_resolution.resized(width, height))
}

fn world_from_camera(
    camera: &CameraFile,
    normalisation: Normalisation,
    file: &str,
) -> Result<Mat4, SceneError> {
    let values = camera.orientation.iter().flatten().chain(&camera.position);
    if values.clone().any(|value| !value.is_finite()) {
        return Err(SceneError::Parse {
            file: file.to_string(),
            message: "orientation and position must be finite".to_string(),
        });
    }
    let row = |index: usize| Vec3::from(camera.orientation[index].map(|value| value as f32));
    // The orientation's rows are the camera axes in world coordinates, so they are the columns
    // of the camera-to-world rotation.
    let world_rotation = Mat3::from_cols(row(0), row(1), row(2));
    if (world_rotation.determinant() - 1.0).abs() > 1e-3 {
        return Err(SceneError::Parse {
            file: file.to_string(),
            message: "orientation is not a rotation matrix".to_string(),
        });
    }
    let position = Vec3::from(camera.position.map(|value| value as f32));
    let mut pose = Mat4::from_mat3(world_rotation);
    pose.w_axis = normalisation.apply(position).extend(1.0);
    Ok(pose)
}

fn read_points(root: &Path, normalisation: Normalisation) -> Result<SparsePoints, SceneError> {
    let matrix = read_float_matrix(root, POINTS_FILE, 3)?;
    let positions: Vec<Vec3> = (0..matrix.rows)
        .map(|index| {
            let row = matrix.row(index);
            normalisation.apply(Vec3::new(row[0] as f32, row[1] as f32, row[2] as f32))
        })
        .collect();
    let count = positions.len();
    Ok(SparsePoints {
        positions,
        colors: vec![Vec3::splat(POINT_GREY); count],
        tracks: vec![Vec::new(); count],
    })
}
