//! The synthetic sphere world (see [`super::synthetic`]) written in the dynamic-scene layouts:
//! Nerfies/HyperNeRF, and Neu3D with extracted frames or as videos. The world does not move; the files still
//! carry times, so loaders, validation and uploads of these formats can be tested end to end.
//! Cameras are stored at twice the images' resolution, as these datasets ship downscaled images
//! with full-resolution cameras, so loading must scale them back to [`synthetic_intrinsics`].

use std::fs;
use std::io;
use std::path::Path;

use glam::{Mat4, Vec3};
use npyz::WriterBuilder;
use serde_json::json;

use super::synthetic::{
    SyntheticSpec, is_synthetic_test_frame, render_view, surface_point_cloud, synthetic_intrinsics,
    synthetic_world_from_cameras, write_image, write_json, write_masks,
};
use super::{nerfies, neu3d};

/// How much larger than the written images the stored cameras are.
pub const FULL_RESOLUTION_FACTOR: u32 = 2;
/// The `scene.json` the Nerfies writer stores: files hold `p / scale + center`, so that the
/// loader's `(p - center) * scale` gives back the synthetic world.
pub const NERFIES_SCENE_CENTER: [f32; 3] = [0.25, -0.5, 1.0];
pub const NERFIES_SCENE_SCALE: f32 = 0.5;

/// Nerfies frame id of synthetic frame `index`.
pub fn nerfies_id(index: usize) -> String {
    format!("{index:06}")
}

/// A Nerfies/HyperNeRF capture: one frame per synthetic camera, `time_id` = frame index,
/// images in `rgb/2x/`, test frames (see [`is_synthetic_test_frame`]) as `val_ids`,
/// `points.npy` (float32) from the sphere surfaces.
pub fn write_nerfies(dir: &Path, spec: &SyntheticSpec) -> io::Result<()> {
    let intrinsics = synthetic_intrinsics(spec);
    let factor = f64::from(FULL_RESOLUTION_FACTOR);
    let center = Vec3::from(NERFIES_SCENE_CENTER);
    let stored = |point: Vec3| point / NERFIES_SCENE_SCALE + center;
    let (mut ids, mut train_ids, mut val_ids) = (Vec::new(), Vec::new(), Vec::new());
    let mut metadata = serde_json::Map::new();
    fs::create_dir_all(dir.join(nerfies::CAMERA_DIR))?;
    for (index, world_from_camera) in synthetic_world_from_cameras(spec).into_iter().enumerate() {
        let id = nerfies_id(index);
        let name = format!("{id}.png");
        let view = render_view(&intrinsics, world_from_camera);
        write_image(
            &dir.join(format!("rgb/{FULL_RESOLUTION_FACTOR}x/{name}")),
            &view,
            super::synthetic::SyntheticImageFormat::Png,
        )?;
        write_masks(dir, spec, &name, &view)?;
        // The orientation's rows are the camera axes, i.e. the pose's rotation columns.
        let orientation: Vec<[f32; 3]> = (0..3)
            .map(|axis| world_from_camera.col(axis).truncate().to_array())
            .collect();
        let camera = json!({
            "orientation": orientation,
            "position": stored(world_from_camera.w_axis.truncate()).to_array(),
            "focal_length": intrinsics.fx * factor,
            "principal_point": [intrinsics.cx * factor, intrinsics.cy * factor],
            "pixel_aspect_ratio": intrinsics.fy / intrinsics.fx,
            "skew": 0.0,
            "radial_distortion": [0.0, 0.0, 0.0],
            "tangential_distortion": [0.0, 0.0],
            "image_size": [spec.width * FULL_RESOLUTION_FACTOR, spec.height * FULL_RESOLUTION_FACTOR],
        });
        write_json(
            &dir.join(format!("{}/{id}.json", nerfies::CAMERA_DIR)),
            &camera,
        )?;
        metadata.insert(
            id.clone(),
            json!({ "time_id": index, "warp_id": index, "appearance_id": index, "camera_id": 0 }),
        );
        if is_synthetic_test_frame(index) {
            val_ids.push(id.clone());
        } else {
            train_ids.push(id.clone());
        }
        ids.push(id);
    }
    write_json(
        &dir.join(nerfies::DATASET_FILE),
        &json!({ "count": ids.len(), "num_exemplars": train_ids.len(),
            "ids": ids, "train_ids": train_ids, "val_ids": val_ids }),
    )?;
    write_json(
        &dir.join("metadata.json"),
        &serde_json::Value::Object(metadata),
    )?;
    write_json(
        &dir.join("scene.json"),
        &json!({ "center": NERFIES_SCENE_CENTER, "scale": NERFIES_SCENE_SCALE,
            "near": 0.1, "far": 10.0 }),
    )?;
    let points: Vec<f32> = surface_point_cloud()
        .positions
        .into_iter()
        .flat_map(|point| stored(point).to_array())
        .collect();
    write_npy_matrix(&dir.join("points.npy"), &points, 3)
}

/// Neu3D camera name for synthetic camera `index`.
pub fn neu3d_camera(index: usize) -> String {
    format!("cam{index:02}")
}

/// A Neu3D capture with extracted frames: one camera per synthetic pose (`cam00` ...), each
/// with `frames_per_camera` identical frames `camNN/images/NNNN.png`, and `poses_bounds.npy`.
pub fn write_neu3d(dir: &Path, spec: &SyntheticSpec, frames_per_camera: usize) -> io::Result<()> {
    let intrinsics = synthetic_intrinsics(spec);
    let poses = synthetic_world_from_cameras(spec);
    for (index, world_from_camera) in poses.iter().enumerate() {
        let view = render_view(&intrinsics, *world_from_camera);
        let camera = neu3d_camera(index);
        for frame in 0..frames_per_camera {
            let file = format!("{frame:04}.png");
            write_image(
                &dir.join(&camera).join(neu3d::FRAMES_DIR).join(&file),
                &view,
                super::synthetic::SyntheticImageFormat::Png,
            )?;
            write_masks(dir, spec, &format!("{camera}/{file}"), &view)?;
        }
    }
    write_synthetic_poses_bounds(dir, spec, &poses)
}

/// A Neu3D capture as recorded: `camNN.mp4` (H.264, 10 fps, `frames_per_camera` frames of the
/// rendered view) and `poses_bounds.npy`, no extracted frames. Encodes with the `ffmpeg`
/// program, which must be installed (scripts/bootstrap.sh installs it).
pub fn write_neu3d_videos(
    dir: &Path,
    spec: &SyntheticSpec,
    frames_per_camera: usize,
) -> io::Result<()> {
    let intrinsics = synthetic_intrinsics(spec);
    let poses = synthetic_world_from_cameras(spec);
    let staging = tempfile::tempdir()?;
    for (index, world_from_camera) in poses.iter().enumerate() {
        let view = render_view(&intrinsics, *world_from_camera);
        for frame in 0..frames_per_camera {
            write_image(
                &staging.path().join(format!("{frame:04}.png")),
                &view,
                super::synthetic::SyntheticImageFormat::Png,
            )?;
        }
        let video = dir.join(format!("{}.mp4", neu3d_camera(index)));
        let output = std::process::Command::new("ffmpeg")
            .args(["-nostdin", "-hide_banner", "-loglevel", "error", "-y"])
            .args(["-framerate", "10", "-i"])
            .arg(staging.path().join("%04d.png"))
            .args(["-c:v", "libx264", "-pix_fmt", "yuv420p"])
            .arg(&video)
            .output()
            .map_err(|error| {
                io::Error::new(
                    error.kind(),
                    format!("cannot run ffmpeg to encode test videos: {error}"),
                )
            })?;
        if !output.status.success() {
            return Err(io::Error::other(format!(
                "ffmpeg could not write {}: {}",
                video.display(),
                String::from_utf8_lossy(&output.stderr)
            )));
        }
    }
    write_synthetic_poses_bounds(dir, spec, &poses)
}

/// The synthetic cameras' `poses_bounds.npy`, at [`FULL_RESOLUTION_FACTOR`] times the images.
fn write_synthetic_poses_bounds(
    dir: &Path,
    spec: &SyntheticSpec,
    poses: &[Mat4],
) -> io::Result<()> {
    let factor = FULL_RESOLUTION_FACTOR;
    write_poses_bounds(
        &dir.join(neu3d::POSES_BOUNDS_FILE),
        poses,
        (spec.width * factor, spec.height * factor),
        synthetic_intrinsics(spec).fx * f64::from(factor),
    )
}

/// `poses_bounds.npy` (float64) for OpenCV camera-to-world `poses` of `width` x `height`
/// images with focal length `focal`: per camera the LLFF 3x5 matrix, whose rotation columns
/// are the camera's down, right and backwards axes, then near 0.1 and far 100.
pub fn write_poses_bounds(
    path: &Path,
    poses: &[Mat4],
    (width, height): (u32, u32),
    focal: f64,
) -> io::Result<()> {
    let mut values = Vec::with_capacity(poses.len() * 17);
    for world_from_camera in poses {
        let axis = |index: usize| world_from_camera.col(index).truncate();
        let columns = [
            axis(1),
            axis(0),
            -axis(2),
            world_from_camera.w_axis.truncate(),
        ];
        let hwf = [f64::from(height), f64::from(width), focal];
        for row in 0..3 {
            values.extend(columns.iter().map(|column| f64::from(column[row])));
            values.push(hwf[row]);
        }
        values.extend([0.1, 100.0]);
    }
    write_npy_matrix(path, &values, 17)
}

/// Writes `values` as an (N, `columns`) array of `T` (float32 or float64 here).
pub fn write_npy_matrix<T: npyz::AutoSerialize + Copy>(
    path: &Path,
    values: &[T],
    columns: u64,
) -> io::Result<()> {
    let mut writer = npyz::WriteOptions::<T>::new()
        .default_dtype()
        .shape(&[values.len() as u64 / columns, columns])
        .writer(io::BufWriter::new(fs::File::create(path)?))
        .begin_nd()?;
    writer.extend(values.iter().copied())?;
    writer.finish()
}
