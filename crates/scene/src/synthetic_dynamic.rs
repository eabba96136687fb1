//! A small dynamic scene with known motion, for tests and benchmarks: the three synthetic spheres
//! move along known paths and spin (each is painted in two tones split by a plane through its
//! axis, so the spin shows), one view per time as in D-NeRF: the camera jumps around the scene
//! from frame to frame (golden-angle azimuths, alternating heights), as D-NeRF's synthetic scenes
//! do, so the views of any short span of time see the objects from many sides. Written as D-NeRF
//! (Blender with `time`) with exact instance masks per frame, so the ground truth of every pixel
//! and every centre is known.

use std::f32::consts::PI;
use std::fs;
use std::io;
use std::path::Path;

use glam::{Mat4, Vec3};

const CAMERA_DISTANCE: f32 = 4.0;
/// Fraction of a turn between consecutive frames' azimuths (the golden ratio's).
const GOLDEN_TURN: f32 = 0.618_034;
use image::{ImageFormat, Luma, Rgba};
use serde_json::json;

use super::Level;
use super::masks::mask_path;
use super::synthetic::{
    SyntheticObject, SyntheticSpec, camera_looking_at_origin, cast_ray, opengl_matrix_rows,
    pixel_ray, synthetic_intrinsics, synthetic_objects, write_blender_transforms,
};

/// The spheres' centres at normalised time `t`: a straight line, an arc, and a bob.
pub fn dynamic_object_center(object_index: usize, t: f32) -> Vec3 {
    let base = synthetic_objects()[object_index % 3].center;
    base + match object_index % 3 {
        0 => Vec3::new(0.0, -0.5 + 0.7 * t, 0.0),
        1 => 0.2 * Vec3::new((PI * t).cos() - 1.0, (PI * t).sin(), 0.0),
        _ => Vec3::new(0.0, 0.05, 0.3 * (PI * t).sin()),
    }
}

/// The spheres' spin about the world z axis at time `t` (radians).
pub fn dynamic_object_spin(object_index: usize, t: f32) -> f32 {
    [PI, -0.5 * PI, 0.0][object_index % 3] * t
}

/// The objects as they are at time `t`.
pub fn dynamic_objects_at(t: f32) -> Vec<SyntheticObject> {
    synthetic_objects()
        .iter()
        .enumerate()
        .map(|(index, object)| SyntheticObject {
            center: dynamic_object_center(index, t),
            ..*object
        })
        .collect()
}

/// Camera-to-world poses (OpenCV axes) of the frames: azimuth advancing by the golden turn,
/// height alternating between three levels, always looking at the origin.
pub fn dynamic_world_from_cameras(spec: &SyntheticSpec) -> Vec<Mat4> {
    (0..spec.frame_count)
        .map(|index| {
            let azimuth = std::f32::consts::TAU * (index as f32 * GOLDEN_TURN).fract();
            let height = [1.5, 0.4, 2.4][index % 3];
            let ring = (CAMERA_DISTANCE * CAMERA_DISTANCE - height * height).sqrt();
            camera_looking_at_origin(Vec3::new(
                ring * azimuth.cos(),
                ring * azimuth.sin(),
                height,
            ))
        })
        .collect()
}

/// Normalised time of frame `index` of `count`.
pub fn dynamic_frame_time(index: usize, count: usize) -> f32 {
    index as f32 / (count.max(2) - 1) as f32
}

/// Held out like the static Blender writer: every fourth frame from index 3, so held-out times
/// lie between training times.
pub fn is_dynamic_test_frame(index: usize) -> bool {
    index % 4 == 3
}

/// Colour and object index per pixel of one view at time `t` (transparent background).
fn render_at(
    spec: &SyntheticSpec,
    world_from_camera: Mat4,
    t: f32,
) -> (image::RgbaImage, Vec<Option<usize>>) {
    let intrinsics = synthetic_intrinsics(spec);
    let objects = dynamic_objects_at(t);
    let mut rgba = image::RgbaImage::new(spec.width, spec.height);
    let mut object_from_pixel = Vec::with_capacity((spec.width * spec.height) as usize);
    for y in 0..spec.height {
        for x in 0..spec.width {
            let (origin, direction) = pixel_ray(
                &intrinsics,
                world_from_camera,
                x as f32 + 0.5,
                y as f32 + 0.5,
            );
            let hit = cast_ray(origin, direction, &objects);
            let pixel = match &hit {
                Some(hit) => {
                    let spin = dynamic_object_spin(hit.object_index, t);
                    // The normal in the sphere's own frame decides the tone.
                    let (sin, cos) = spin.sin_cos();
                    let local_x = cos * hit.normal.x + sin * hit.normal.y;
                    let tone = if local_x >= 0.0 { 1.0 } else { 0.55 };
                    let shade = (0.55 + 0.45 * hit.normal.dot(-direction).max(0.0)) * tone;
                    let color = objects[hit.object_index].color;
                    let [r, g, b] = color.map(|channel| (f32::from(channel) * shade) as u8);
                    Rgba([r, g, b, 255])
                }
                None => Rgba([0, 0, 0, 0]),
            };
            rgba.put_pixel(x, y, pixel);
            object_from_pixel.push(hit.map(|hit| hit.object_index));
        }
    }
    (rgba, object_from_pixel)
}

/// Writes the scene as D-NeRF: `train/` and `test/` RGBA PNGs, `transforms_{train,test}.json`
/// with `time`, and (when `spec.with_masks` names levels) `masks/<level>/<split>/r_<i>.png`.
pub fn write_dynamic_blender(dir: &Path, spec: &SyntheticSpec) -> io::Result<()> {
    let intrinsics = synthetic_intrinsics(spec);
    let camera_angle_x = 2.0 * (0.5 * f64::from(spec.width) / intrinsics.fx).atan();
    let objects = synthetic_objects();
    let (mut train, mut test) = (Vec::new(), Vec::new());
    let poses = dynamic_world_from_cameras(spec);
    for (index, world_from_camera) in poses.into_iter().enumerate() {
        let t = dynamic_frame_time(index, spec.frame_count);
        let split = if is_dynamic_test_frame(index) {
            "test"
        } else {
            "train"
        };
        let stem = format!("{split}/r_{index}");
        let (rgba, object_from_pixel) = render_at(spec, world_from_camera, t);
        let path = dir.join(format!("{stem}.png"));
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent)?;
        }
        rgba.save_with_format(&path, ImageFormat::Png)
            .map_err(io::Error::other)?;
        for level in spec.with_masks.iter().flatten() {
            let mask = dir.join(mask_path(*level, &format!("{stem}.png")));
            if let Some(parent) = mask.parent() {
                fs::create_dir_all(parent)?;
            }
            image::GrayImage::from_fn(spec.width, spec.height, |x, y| {
                let object = object_from_pixel[(y * spec.width + x) as usize];
                Luma([object.map_or(0, |i| objects[i].ids[level.index()] as u8)])
            })
            .save_with_format(&mask, ImageFormat::Png)
            .map_err(io::Error::other)?;
        }
        let frame = json!({
            "file_path": format!("./{stem}"),
            "rotation": 0.0,
            "time": t,
            "transform_matrix": opengl_matrix_rows(world_from_camera),
        });
        if split == "test" {
            test.push(frame);
        } else {
            train.push(frame);
        }
    }
    write_blender_transforms(dir, camera_angle_x, train, test)
}

/// The true instance ids of a view at time `t` for `level` (0 = background), row-major.
pub fn dynamic_true_mask(
    spec: &SyntheticSpec,
    world_from_camera: Mat4,
    t: f32,
    level: Level,
) -> Vec<u32> {
    let objects = synthetic_objects();
    let (_, object_from_pixel) = render_at(spec, world_from_camera, t);
    object_from_pixel
        .iter()
        .map(|object| object.map_or(0, |i| objects[i].ids[level.index()]))
        .collect()
}
