//! The three-sphere world written out in each still-scene format the loaders read: COLMAP,
//! nerfstudio and Blender NeRF.

use std::fs;
use std::io;
use std::path::Path;

use glam::Mat4;
use image::ImageFormat;
use serde_json::json;

use super::{
    NERFSTUDIO_POINTS_FILE, SyntheticLens, SyntheticSpec, observe, render_distorted_view,
    render_view, surface_point_cloud, surface_points, synthetic_camera, synthetic_intrinsics,
    synthetic_objects, synthetic_world_from_cameras, write_image, write_masks,
};
use crate::colmap::{
    self, CameraModel, ColmapCamera, ColmapEncoding, ColmapImage, ColmapKeypoint, ColmapModel,
    ColmapPoint, ColmapTrackElement,
};
use crate::point_ply::write_point_ply;
use crate::transforms_json::opencv_from_opengl_camera;
use crate::{blender, nerfstudio};

/// A COLMAP dataset: `images/frame_NNNN.<ext>` and `sparse/0/` in the given encoding, one
/// PINHOLE camera (or the spec's lens model), images listed in reverse name order (loaders must
/// sort), points with tracks (keypoints where the lens puts them).
pub fn write_colmap(dir: &Path, spec: &SyntheticSpec, encoding: ColmapEncoding) -> io::Result<()> {
    let (intrinsics, lens) = synthetic_camera(spec)?;
    let camera_model = spec
        .lens
        .as_ref()
        .map_or(CameraModel::Pinhole, |lens| lens.model);
    let poses = synthetic_world_from_cameras(spec);
    let mut model = ColmapModel::default();
    model.cameras.insert(
        1,
        ColmapCamera {
            id: 1,
            model: camera_model,
            width: u64::from(spec.width),
            height: u64::from(spec.height),
            params: camera_model.params_from_intrinsics(&intrinsics),
        },
    );
    for (index, world_from_camera) in poses.iter().enumerate() {
        let name = format!("frame_{index:04}.{}", spec.image_format.extension());
        let view = render_distorted_view(&intrinsics, &lens, *world_from_camera);
        write_image(
            &dir.join(colmap::IMAGES_DIR).join(&name),
            &view,
            spec.image_format,
        )?;
        write_masks(dir, spec, &name, &view)?;
        let (qvec, tvec) = colmap::colmap_pose_from_world_from_camera(*world_from_camera);
        model.images.push(ColmapImage {
            id: index as u32 + 1,
            qvec,
            tvec,
            camera_id: 1,
            name,
            points2d: Vec::new(),
        });
    }
    for (point_index, (object_index, position)) in surface_points().into_iter().enumerate() {
        let point_id = point_index as u64 + 1;
        let mut track = Vec::new();
        for (image, world_from_camera) in model.images.iter_mut().zip(&poses) {
            if let Some(xy) = observe(
                position,
                object_index,
                &intrinsics,
                &lens,
                *world_from_camera,
            ) {
                track.push(ColmapTrackElement {
                    image_id: image.id,
                    point2d_index: image.points2d.len() as u32,
                });
                image.points2d.push(ColmapKeypoint {
                    xy,
                    point3d_id: point_id as i64,
                });
            }
        }
        model.points.push(ColmapPoint {
            id: point_id,
            xyz: position.as_dvec3().to_array(),
            rgb: synthetic_objects()[object_index].color,
            error: 0.5,
            track,
        });
    }
    model.images.reverse();
    colmap::write_model(&dir.join("sparse/0"), &model, encoding)
}

/// Rows of an OpenGL camera-to-world matrix, as the transforms files store it.
pub(crate) fn opengl_matrix_rows(world_from_camera: Mat4) -> Vec<Vec<f64>> {
    let opengl = world_from_camera * opencv_from_opengl_camera();
    (0..4)
        .map(|row| {
            opengl
                .row(row)
                .to_array()
                .iter()
                .map(|v| f64::from(*v))
                .collect()
        })
        .collect()
}

/// A nerfstudio dataset: `transforms.json` (global OPENCV intrinsics with zero distortion, or the
/// spec's lens as nerfstudio's fields, frames in reverse order), `images/frame_NNNN.<ext>` and
/// the surface points as `sparse_pc.ply`.
pub fn write_nerfstudio(dir: &Path, spec: &SyntheticSpec) -> io::Result<()> {
    let (intrinsics, lens) = synthetic_camera(spec)?;
    let lens_fields = nerfstudio_lens_fields(spec.lens.as_ref())?;
    let mut frames = Vec::new();
    for (index, world_from_camera) in synthetic_world_from_cameras(spec).into_iter().enumerate() {
        let name = format!("frame_{index:04}.{}", spec.image_format.extension());
        let view = render_distorted_view(&intrinsics, &lens, world_from_camera);
        write_image(&dir.join("images").join(&name), &view, spec.image_format)?;
        write_masks(dir, spec, &name, &view)?;
        frames.push(json!({
            "file_path": format!("images/{name}"),
            "transform_matrix": opengl_matrix_rows(world_from_camera),
        }));
    }
    frames.reverse();
    write_point_ply(&dir.join(NERFSTUDIO_POINTS_FILE), &surface_point_cloud())?;
    let mut transforms = json!({
        "ply_file_path": NERFSTUDIO_POINTS_FILE,
        "fl_x": intrinsics.fx, "fl_y": intrinsics.fy,
        "cx": intrinsics.cx, "cy": intrinsics.cy,
        "w": intrinsics.width, "h": intrinsics.height,
        "frames": frames,
    });
    for (field, value) in lens_fields {
        transforms[field] = value;
    }
    write_json(&dir.join(nerfstudio::TRANSFORMS_FILE), &transforms)
}

/// `camera_model` and the distortion fields of transforms.json for a lens.
fn nerfstudio_lens_fields(
    lens: Option<&SyntheticLens>,
) -> io::Result<Vec<(&'static str, serde_json::Value)>> {
    let Some(lens) = lens else {
        return Ok(vec![
            ("camera_model", json!("OPENCV")),
            ("k1", json!(0.0)),
            ("k2", json!(0.0)),
            ("p1", json!(0.0)),
            ("p2", json!(0.0)),
        ]);
    };
    let (camera_model, names): (&str, &[&'static str]) = match lens.model {
        CameraModel::OpenCv => ("OPENCV", &["k1", "k2", "p1", "p2"]),
        CameraModel::FullOpenCv => ("OPENCV", &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"]),
        CameraModel::OpenCvFisheye => ("OPENCV_FISHEYE", &["k1", "k2", "k3", "k4"]),
        other => {
            return Err(io::Error::other(format!(
                "nerfstudio's transforms.json cannot express a {} camera",
                other.name()
            )));
        }
    };
    if names.len() != lens.distortion.len() {
        return Err(io::Error::other(format!(
            "{} takes {} distortion parameters, {} given",
            lens.model.name(),
            names.len(),
            lens.distortion.len()
        )));
    }
    let mut fields = vec![("camera_model", json!(camera_model))];
    fields.extend(
        names
            .iter()
            .zip(&lens.distortion)
            .map(|(name, value)| (*name, json!(value))),
    );
    Ok(fields)
}

/// Which frames the Blender writer puts in the test split: every fourth, starting at index 3.
pub fn is_synthetic_test_frame(index: usize) -> bool {
    index % 4 == 3
}

/// A Blender NeRF dataset: RGBA PNGs (transparent background) under `train/` and `test/`,
/// `file_path` without extension, `transforms_train.json` and `transforms_test.json`.
pub fn write_blender(dir: &Path, spec: &SyntheticSpec) -> io::Result<()> {
    let intrinsics = synthetic_intrinsics(spec);
    let camera_angle_x = 2.0 * (0.5 * f64::from(spec.width) / intrinsics.fx).atan();
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (index, world_from_camera) in synthetic_world_from_cameras(spec).into_iter().enumerate() {
        let split = if is_synthetic_test_frame(index) {
            "test"
        } else {
            "train"
        };
        let stem = format!("{split}/r_{index}");
        let view = render_view(&intrinsics, world_from_camera);
        let path = dir.join(format!("{stem}.png"));
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent)?;
        }
        view.rgba
            .save_with_format(&path, ImageFormat::Png)
            .map_err(io::Error::other)?;
        write_masks(dir, spec, &format!("{stem}.png"), &view)?;
        let mut frame = json!({
            "file_path": format!("./{stem}"),
            "rotation": 0.0,
            "transform_matrix": opengl_matrix_rows(world_from_camera),
        });
        if spec.with_time {
            let time = index as f64 / (spec.frame_count.max(2) - 1) as f64;
            frame["time"] = json!(time);
        }
        if split == "test" {
            test.push(frame)
        } else {
            train.push(frame)
        }
    }
    write_blender_transforms(dir, camera_angle_x, train, test)
}

/// `transforms_train.json` and `transforms_test.json` of a Blender dataset from its frames.
pub(crate) fn write_blender_transforms(
    dir: &Path,
    camera_angle_x: f64,
    train: Vec<serde_json::Value>,
    test: Vec<serde_json::Value>,
) -> io::Result<()> {
    for (file, frames) in [
        (blender::TRAIN_TRANSFORMS_FILE, train),
        (blender::TEST_TRANSFORMS_FILE, test),
    ] {
        write_json(
            &dir.join(file),
            &json!({ "camera_angle_x": camera_angle_x, "frames": frames }),
        )?;
    }
    Ok(())
}

pub(crate) fn write_json(path: &Path, value: &serde_json::Value) -> io::Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(io::Error::other)?;
    fs::write(path, text)
}
