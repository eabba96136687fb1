//! COLMAP datasets: `sparse/0/` (or `sparse/`) holding a binary or text model, images under
//! `images/`. Poses are converted from COLMAP's world-to-camera to `world_from_camera`; both use
//! the OpenCV camera convention, so no axis flip is needed.

pub mod binary;
pub mod camera_models;
pub mod model;
pub mod text;

use std::collections::HashMap;
use std::io;
use std::path::{Path, PathBuf};

use glam::{DMat3, DMat4, DQuat, DVec3, Vec3};

pub use camera_models::CameraModel;
pub use model::{
    ColmapCamera, ColmapImage, ColmapKeypoint, ColmapModel, ColmapPoint, ColmapTrackElement,
};

use super::dataset_path::contained_relative_path;
use super::distortion::{Lens, undistort_pixel};
use super::{Frame, LoadOptions, Scene, SceneError, SceneFormat, SparsePoints, TrackObservation};

/// Folder (relative to the dataset root) holding the images a COLMAP model names.
pub const IMAGES_DIR: &str = "images";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColmapEncoding {
    Text,
    Binary,
}

/// Where the sparse model is, relative to the dataset root, and how it is encoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModelLocation {
    pub relative_dir: PathBuf,
    pub encoding: ColmapEncoding,
}

/// `sparse/0` first, then `sparse`; binary files win over text when both are present, as in
/// COLMAP itself.
pub fn find_model(root: &Path) -> Option<ModelLocation> {
    ["sparse/0", "sparse"].into_iter().find_map(|candidate| {
        let dir = root.join(candidate);
        let encoding = if dir.join("cameras.bin").is_file() {
            ColmapEncoding::Binary
        } else if dir.join("cameras.txt").is_file() {
            ColmapEncoding::Text
        } else {
            return None;
        };
        Some(ModelLocation {
            relative_dir: PathBuf::from(candidate),
            encoding,
        })
    })
}

pub fn read_model(root: &Path, location: &ModelLocation) -> Result<ColmapModel, SceneError> {
    let dir = root.join(&location.relative_dir);
    let display_dir = location.relative_dir.display().to_string();
    match location.encoding {
        ColmapEncoding::Binary => binary::read_model(&dir, &display_dir),
        ColmapEncoding::Text => text::read_model(&dir, &display_dir),
    }
}

/// Writes `model` into `dir` (created if needed) in the given encoding.
pub fn write_model(dir: &Path, model: &ColmapModel, encoding: ColmapEncoding) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    match encoding {
        ColmapEncoding::Binary => binary::write_model(dir, model),
        ColmapEncoding::Text => text::write_model(dir, model),
    }
}

/// Parses the COLMAP dataset at `root` (the model must be at `location`).
pub fn load_colmap(
    root: &Path,
    location: &ModelLocation,
    options: &LoadOptions,
) -> Result<Scene, SceneError> {
    let model = read_model(root, location)?;
    let display_dir = location.relative_dir.display().to_string();
    scene_from_model(root, &model, &display_dir, options)
}

/// Converts a parsed model; frames are sorted by image name.
pub fn scene_from_model(
    root: &Path,
    model: &ColmapModel,
    display_dir: &str,
    options: &LoadOptions,
) -> Result<Scene, SceneError> {
    let images_file = || format!("{display_dir}/images");
    if model.images.is_empty() {
        return Err(SceneError::Inconsistent {
            file: images_file(),
            message: "the model has no registered images".to_string(),
        });
    }
    let mut image_order: Vec<usize> = (0..model.images.len()).collect();
    image_order.sort_by(|a, b| model.images[*a].name.cmp(&model.images[*b].name));

    let mut frames = Vec::with_capacity(model.images.len());
    let mut lenses = Vec::with_capacity(model.images.len());
    let mut frame_index_from_image_id = HashMap::with_capacity(model.images.len());
    for image_index in image_order {
        let image = &model.images[image_index];
        let camera = model
            .cameras
            .get(&image.camera_id)
            .ok_or_else(|| SceneError::Parse {
                file: images_file(),
                message: format!(
                    "image {} ({}) uses camera {} which the cameras file does not define",
                    image.id, image.name, image.camera_id
                ),
            })?;
        let parse_error = |message: String| SceneError::Parse {
            file: format!("{display_dir}/cameras"),
            message: format!("camera {}: {message}", camera.id),
        };
        let width = u32::try_from(camera.width)
            .map_err(|_| parse_error(format!("width {} is too large", camera.width)))?;
        let height = u32::try_from(camera.height)
            .map_err(|_| parse_error(format!("height {} is too large", camera.height)))?;
        let intrinsics = camera
            .model
            .intrinsics(width, height, &camera.params)
            .ok_or_else(|| parse_error("wrong parameter count for its model".to_string()))?;
        let lens = Lens::from_intrinsics(&intrinsics).map_err(parse_error)?;
        if frame_index_from_image_id
            .insert(image.id, frames.len() as u32)
            .is_some()
        {
            return Err(SceneError::Parse {
                file: images_file(),
                message: format!("image id {} appears twice", image.id),
            });
        }
        let name_path = contained_relative_path(&image.name).ok_or_else(|| SceneError::Parse {
            file: images_file(),
            message: format!(
                "image {}: name {:?} must be a path inside the images folder",
                image.id, image.name
            ),
        })?;
        lenses.push(lens);
        frames.push(Frame {
            name: image.name.clone(),
            image_path: Path::new(IMAGES_DIR).join(name_path),
            intrinsics,
            world_from_camera: world_from_camera(image.qvec, image.tvec),
            time: None,
            source_id: Some(image.id),
            split: None,
        });
    }

    let points = sparse_points(
        model,
        &frame_index_from_image_id,
        &frames,
        &lenses,
        display_dir,
    )?;
    Ok(Scene {
        root: root.to_path_buf(),
        format: SceneFormat::Colmap,
        frames,
        points: Some(points),
        masks: None,
        background: options.background,
    })
}

/// COLMAP stores `camera_from_world` as a unit quaternion (w, x, y, z) and translation.
pub fn world_from_camera(qvec: [f64; 4], tvec: [f64; 3]) -> glam::Mat4 {
    let [w, x, y, z] = qvec;
    let rotation = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w).normalize());
    let translation = DVec3::from_array(tvec);
    let rotation_inverse = rotation.transpose();
    DMat4::from_mat3_translation(rotation_inverse, -(rotation_inverse * translation)).as_mat4()
}

/// The inverse of [`world_from_camera`], for writers: (qvec w,x,y,z; tvec).
pub fn colmap_pose_from_world_from_camera(world_from_camera: glam::Mat4) -> ([f64; 4], [f64; 3]) {
    let camera_from_world = world_from_camera.as_dmat4().inverse();
    let (_, rotation, translation) = camera_from_world.to_scale_rotation_translation();
    let rotation = rotation.normalize();
    (
        [rotation.w, rotation.x, rotation.y, rotation.z],
        translation.to_array(),
    )
}

/// The model's points with their tracks; keypoints of distorted cameras are undistorted to the
/// pinhole camera the frames are loaded as (an observation whose undistortion does not converge
/// is left out).
fn sparse_points(
    model: &ColmapModel,
    frame_index_from_image_id: &HashMap<u32, u32>,
    frames: &[Frame],
    lenses: &[Lens],
    display_dir: &str,
) -> Result<SparsePoints, SceneError> {
    let mut dropped_observations = 0usize;
    let image_from_id: HashMap<u32, &ColmapImage> =
        model.images.iter().map(|image| (image.id, image)).collect();
    let mut points = SparsePoints {
        positions: Vec::with_capacity(model.points.len()),
        colors: Vec::with_capacity(model.points.len()),
        tracks: Vec::with_capacity(model.points.len()),
    };
    for point in &model.points {
        let track_error = |message: String| SceneError::Parse {
            file: format!("{display_dir}/points3D"),
            message: format!("point {}: {message}", point.id),
        };
        let mut track = Vec::with_capacity(point.track.len());
        for element in &point.track {
            let (Some(frame_index), Some(image)) = (
                frame_index_from_image_id.get(&element.image_id),
                image_from_id.get(&element.image_id),
            ) else {
                return Err(track_error(format!(
                    "track names image {} which the images file does not define",
                    element.image_id
                )));
            };
            let keypoint = image
                .points2d
                .get(element.point2d_index as usize)
                .ok_or_else(|| {
                    track_error(format!(
                        "track names keypoint {} of image {} which has {} keypoints",
                        element.point2d_index,
                        element.image_id,
                        image.points2d.len()
                    ))
                })?;
            let index = *frame_index as usize;
            let lens = &lenses[index];
            let xy = if lens.is_pinhole() {
                Some(keypoint.xy)
            } else {
                undistort_pixel(&frames[index].intrinsics, lens, keypoint.xy)
            };
            let Some([x, y]) = xy else {
                dropped_observations += 1;
                continue;
            };
            track.push(TrackObservation {
                frame_index: *frame_index,
                pixel: [x as f32, y as f32],
            });
        }
        let [x, y, z] = point.xyz;
        points
            .positions
            .push(Vec3::new(x as f32, y as f32, z as f32));
        points.colors.push(Vec3::from_array(
            point.rgb.map(|channel| f32::from(channel) / 255.0),
        ));
        points.tracks.push(track);
    }
    if dropped_observations > 0 {
        tracing::warn!(
            dropped_observations,
            "keypoints whose undistortion did not converge were left out of the point tracks"
        );
    }
    Ok(points)
}
