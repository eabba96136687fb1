//! Small, valid, self-consistent datasets written to a directory, for tests across the project.
//!
//! The world is a few coloured spheres around the origin; cameras sit on a circle looking at the
//! origin; each image is an exact ray-cast of the spheres, masks are the sphere ids at three
//! granularities, and the sparse points lie on the sphere surfaces with tracks to the frames
//! that actually see them. So poses, images, points and masks all agree.

use std::f32::consts::TAU;
use std::fs;
use std::io;
use std::path::Path;

use glam::{Mat4, Vec3};
use image::{ImageFormat, Luma, Rgb, Rgba};

use super::colmap::{CameraModel, ColmapEncoding};
use super::distortion::{Lens, distort_pixel, undistort_pixel};
use super::masks::mask_path;
use super::{Intrinsics, Level, SparsePoints};

mod writers;

pub use writers::{is_synthetic_test_frame, write_blender, write_colmap, write_nerfstudio};
pub(crate) use writers::{opengl_matrix_rows, write_blender_transforms, write_json};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SyntheticImageFormat {
    Png,
    Jpeg,
}

impl SyntheticImageFormat {
    pub(super) fn extension(self) -> &'static str {
        match self {
            SyntheticImageFormat::Png => "png",
            SyntheticImageFormat::Jpeg => "jpg",
        }
    }
}

#[derive(Debug, Clone)]
pub struct SyntheticSpec {
    pub frame_count: usize,
    pub width: u32,
    pub height: u32,
    /// Mask levels to write (`masks/<level>/...`); `None` writes no masks.
    pub with_masks: Option<Vec<Level>>,
    /// Image encoding for COLMAP and nerfstudio (Blender always writes RGBA PNG).
    pub image_format: SyntheticImageFormat,
    /// Blender only: write a D-NeRF `time` per frame (frame index / (count - 1)).
    pub with_time: bool,
    /// COLMAP and nerfstudio only: a distorted camera. Images, masks and keypoints are then
    /// ray-cast through the distorted lens (each pixel's ray found by undistorting it), with the
    /// pinhole [`synthetic_intrinsics`] as `fx, fy, cx, cy`; `None` writes a pinhole camera.
    pub lens: Option<SyntheticLens>,
    /// Distance of the cameras from the world's vertical axis (4 by default; about 2 puts the
    /// spheres near the edges of the frame, where lens distortion is strongest).
    pub camera_distance: f32,
}

/// A lens for [`SyntheticSpec::lens`]: a COLMAP model and its distortion parameters in COLMAP's
/// order (e.g. OPENCV `k1 k2 p1 p2`). nerfstudio can write OPENCV, FULL_OPENCV and
/// OPENCV_FISHEYE.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticLens {
    pub model: CameraModel,
    pub distortion: Vec<f64>,
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        Self {
            frame_count: 6,
            width: 32,
            height: 24,
            with_masks: None,
            image_format: SyntheticImageFormat::Png,
            with_time: false,
            lens: None,
            camera_distance: CAMERA_DISTANCE,
        }
    }
}

/// One sphere of the synthetic world, with its instance id at each mask level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticObject {
    pub center: Vec3,
    pub radius: f32,
    pub color: [u8; 3],
    /// Instance ids at small, middle, large.
    pub ids: [u32; 3],
}

/// Three spheres: at the small level each is its own object, at the middle level the first two
/// are one object, at the large level all three are one.
pub fn synthetic_objects() -> [SyntheticObject; 3] {
    [
        SyntheticObject {
            center: Vec3::new(-0.6, 0.0, 0.0),
            radius: 0.45,
            color: [220, 60, 50],
            ids: [1, 1, 1],
        },
        SyntheticObject {
            center: Vec3::new(0.5, -0.3, 0.1),
            radius: 0.4,
            color: [60, 190, 80],
            ids: [2, 1, 1],
        },
        SyntheticObject {
            center: Vec3::new(0.1, 0.6, -0.2),
            radius: 0.35,
            color: [50, 90, 220],
            ids: [3, 2, 1],
        },
    ]
}

/// Background grey of the COLMAP and nerfstudio images.
pub const SYNTHETIC_BACKGROUND: [u8; 3] = [40, 40, 40];

const CAMERA_DISTANCE: f32 = 4.0;
const CAMERA_HEIGHT: f32 = 1.5;
const POINTS_PER_OBJECT: usize = 48;
const NERFSTUDIO_POINTS_FILE: &str = "sparse_pc.ply";

/// Pinhole intrinsics shared by every synthetic frame (horizontal field of view about 58 degrees).
pub fn synthetic_intrinsics(spec: &SyntheticSpec) -> Intrinsics {
    let focal = 0.9 * f64::from(spec.width);
    Intrinsics {
        width: spec.width,
        height: spec.height,
        fx: focal,
        fy: focal,
        cx: f64::from(spec.width) / 2.0,
        cy: f64::from(spec.height) / 2.0,
        model: CameraModel::Pinhole.name().to_string(),
        distortion: Vec::new(),
    }
}

/// The camera the COLMAP and nerfstudio writers store: [`synthetic_intrinsics`] with the spec's
/// lens model and distortion, and that lens.
pub fn synthetic_camera(spec: &SyntheticSpec) -> io::Result<(Intrinsics, Lens)> {
    let mut camera = synthetic_intrinsics(spec);
    if let Some(lens) = &spec.lens {
        camera.model = lens.model.name().to_string();
        camera.distortion = lens.distortion.clone();
    }
    let lens = Lens::from_intrinsics(&camera).map_err(io::Error::other)?;
    Ok((camera, lens))
}

/// Camera-to-world poses (OpenCV convention), on a circle around the z axis (world up = +z),
/// each looking at the origin.
pub fn synthetic_world_from_cameras(spec: &SyntheticSpec) -> Vec<Mat4> {
    (0..spec.frame_count)
        .map(|index| {
            let angle = TAU * index as f32 / spec.frame_count.max(1) as f32;
            let eye = Vec3::new(
                spec.camera_distance * angle.cos(),
                spec.camera_distance * angle.sin(),
                CAMERA_HEIGHT,
            );
            camera_looking_at_origin(eye)
        })
        .collect()
}

/// Camera-to-world (OpenCV axes) of a camera at `eye` looking at the origin, world up = +z.
pub(crate) fn camera_looking_at_origin(eye: Vec3) -> Mat4 {
    let forward = (-eye).normalize();
    let right = forward.cross(Vec3::Z).normalize();
    let down = forward.cross(right);
    Mat4::from_cols(
        right.extend(0.0),
        down.extend(0.0),
        forward.extend(0.0),
        eye.extend(1.0),
    )
}

/// What a camera sees through one pixel centre: the nearest object hit, with the hit distance
/// and the surface normal there.
pub(crate) struct RayHit {
    pub object_index: usize,
    pub distance: f32,
    pub normal: Vec3,
}

pub(crate) fn cast_ray(
    origin: Vec3,
    direction: Vec3,
    objects: &[SyntheticObject],
) -> Option<RayHit> {
    objects
        .iter()
        .enumerate()
        .filter_map(|(object_index, object)| {
            let to_origin = origin - object.center;
            let b = to_origin.dot(direction);
            let c = to_origin.length_squared() - object.radius * object.radius;
            let discriminant = b * b - c;
            if discriminant < 0.0 {
                return None;
            }
            let distance = -b - discriminant.sqrt();
            (distance > 0.0).then(|| RayHit {
                object_index,
                distance,
                normal: (origin + direction * distance - object.center).normalize(),
            })
        })
        .min_by(|a, b| a.distance.total_cmp(&b.distance))
}

pub(crate) fn pixel_ray(
    intrinsics: &Intrinsics,
    world_from_camera: Mat4,
    u: f32,
    v: f32,
) -> (Vec3, Vec3) {
    let camera_direction = Vec3::new(
        (u - intrinsics.cx as f32) / intrinsics.fx as f32,
        (v - intrinsics.cy as f32) / intrinsics.fy as f32,
        1.0,
    );
    let origin = world_from_camera.transform_point3(Vec3::ZERO);
    let direction = world_from_camera
        .transform_vector3(camera_direction)
        .normalize();
    (origin, direction)
}

/// One rendered view: colour with coverage, and the object index per pixel.
pub(super) struct RenderedView {
    pub(super) rgba: image::RgbaImage,
    object_from_pixel: Vec<Option<usize>>,
}

pub(super) fn render_view(intrinsics: &Intrinsics, world_from_camera: Mat4) -> RenderedView {
    render_distorted_view(intrinsics, &Lens::Pinhole, world_from_camera)
}

/// [`render_view`] through a distorted lens: each pixel centre is undistorted to find its ray
/// (pixels whose undistortion fails see nothing).
pub(super) fn render_distorted_view(
    intrinsics: &Intrinsics,
    lens: &Lens,
    world_from_camera: Mat4,
) -> RenderedView {
    let objects = synthetic_objects();
    let (width, height) = (intrinsics.width, intrinsics.height);
    let mut rgba = image::RgbaImage::new(width, height);
    let mut object_from_pixel = Vec::with_capacity((width * height) as usize);
    for y in 0..height {
        for x in 0..width {
            let centre = [f64::from(x) + 0.5, f64::from(y) + 0.5];
            let pinhole_pixel = if lens.is_pinhole() {
                Some(centre)
            } else {
                undistort_pixel(intrinsics, lens, centre)
            };
            let hit = pinhole_pixel.and_then(|[u, v]| {
                let (origin, direction) =
                    pixel_ray(intrinsics, world_from_camera, u as f32, v as f32);
                let hit = cast_ray(origin, direction, &objects)?;
                Some((hit, direction))
            });
            let pixel = match &hit {
                Some((hit, direction)) => {
                    let shade = 0.55 + 0.45 * hit.normal.dot(-direction).max(0.0);
                    let color = objects[hit.object_index].color;
                    let [r, g, b] = color.map(|channel| (f32::from(channel) * shade) as u8);
                    Rgba([r, g, b, 255])
                }
                None => {
                    let [r, g, b] = SYNTHETIC_BACKGROUND;
                    Rgba([r, g, b, 0])
                }
            };
            rgba.put_pixel(x, y, pixel);
            object_from_pixel.push(hit.map(|(hit, _)| hit.object_index));
        }
    }
    RenderedView {
        rgba,
        object_from_pixel,
    }
}

/// Points spread evenly over each sphere (Fibonacci lattice).
fn surface_points() -> Vec<(usize, Vec3)> {
    let golden_angle = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    synthetic_objects()
        .iter()
        .enumerate()
        .flat_map(|(object_index, object)| {
            (0..POINTS_PER_OBJECT).map(move |index| {
                let z = 1.0 - 2.0 * (index as f32 + 0.5) / POINTS_PER_OBJECT as f32;
                let ring = (1.0 - z * z).sqrt();
                let angle = golden_angle * index as f32;
                let unit = Vec3::new(ring * angle.cos(), ring * angle.sin(), z);
                (object_index, object.center + unit * object.radius)
            })
        })
        .collect()
}

/// The surface points with their object colours, without tracks.
pub(super) fn surface_point_cloud() -> SparsePoints {
    let objects = synthetic_objects();
    let points = surface_points();
    SparsePoints {
        colors: points
            .iter()
            .map(|(object_index, _)| {
                Vec3::from_array(objects[*object_index].color.map(|c| f32::from(c) / 255.0))
            })
            .collect(),
        positions: points.iter().map(|(_, position)| *position).collect(),
        tracks: vec![Vec::new(); points.len()],
    }
}

/// Pixel position of `point` in a view (through `lens`), when the view sees that point
/// unoccluded.
fn observe(
    point: Vec3,
    object_index: usize,
    intrinsics: &Intrinsics,
    lens: &Lens,
    world_from_camera: Mat4,
) -> Option<[f64; 2]> {
    let camera_point = world_from_camera.inverse().transform_point3(point);
    if camera_point.z <= 0.0 {
        return None;
    }
    let u = intrinsics.fx as f32 * camera_point.x / camera_point.z + intrinsics.cx as f32;
    let v = intrinsics.fy as f32 * camera_point.y / camera_point.z + intrinsics.cy as f32;
    let pinhole = [f64::from(u), f64::from(v)];
    let [du, dv] = if lens.is_pinhole() {
        pinhole
    } else {
        distort_pixel(intrinsics, lens, pinhole)
    };
    let inside = du >= 0.0
        && dv >= 0.0
        && du < f64::from(intrinsics.width)
        && dv < f64::from(intrinsics.height);
    if !inside {
        return None;
    }
    let (origin, direction) = pixel_ray(intrinsics, world_from_camera, u, v);
    let hit = cast_ray(origin, direction, &synthetic_objects())?;
    let distance = (point - origin).length();
    let visible = hit.object_index == object_index && (hit.distance - distance).abs() < 1e-2;
    visible.then_some([du, dv])
}

pub(super) fn write_image(
    path: &Path,
    view: &RenderedView,
    format: SyntheticImageFormat,
) -> io::Result<()> {
    if let Some(parent) = path.parent() {
        fs::create_dir_all(parent)?;
    }
    let rgb = image::RgbImage::from_fn(view.rgba.width(), view.rgba.height(), |x, y| {
        let [r, g, b, _] = view.rgba.get_pixel(x, y).0;
        Rgb([r, g, b])
    });
    let image_format = match format {
        SyntheticImageFormat::Png => ImageFormat::Png,
        SyntheticImageFormat::Jpeg => ImageFormat::Jpeg,
    };
    rgb.save_with_format(path, image_format)
        .map_err(io::Error::other)
}

/// Writes masks for `frame_name` at every requested level: small and large as 8-bit, middle as
/// 16-bit, so both depths get exercised.
pub(super) fn write_masks(
    dir: &Path,
    spec: &SyntheticSpec,
    frame_name: &str,
    view: &RenderedView,
) -> io::Result<()> {
    let Some(levels) = &spec.with_masks else {
        return Ok(());
    };
    let objects = synthetic_objects();
    for level in levels {
        let path = dir.join(mask_path(*level, frame_name));
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent)?;
        }
        let id_at = |x: u32, y: u32| {
            view.object_from_pixel[(y * spec.width + x) as usize]
                .map_or(0, |object_index| objects[object_index].ids[level.index()])
        };
        let saved = if *level == Level::Middle {
            image::ImageBuffer::<Luma<u16>, Vec<u16>>::from_fn(spec.width, spec.height, |x, y| {
                Luma([id_at(x, y) as u16])
            })
            .save_with_format(&path, ImageFormat::Png)
        } else {
            image::GrayImage::from_fn(spec.width, spec.height, |x, y| Luma([id_at(x, y) as u8]))
                .save_with_format(&path, ImageFormat::Png)
        };
        saved.map_err(io::Error::other)?;
    }
    Ok(())
}

/// The three-sphere scene at `width` x `height`, `frames` views and masks at every level, written
/// to `dir` as binary COLMAP and loaded: the standard small scene of the method's tests.
pub fn load_three_spheres(
    dir: &Path,
    frames: usize,
    width: u32,
    height: u32,
) -> Result<crate::Scene, crate::SceneError> {
    let spec = SyntheticSpec {
        frame_count: frames,
        width,
        height,
        with_masks: Some(crate::Level::ALL.to_vec()),
        ..SyntheticSpec::default()
    };
    write_colmap(dir, &spec, ColmapEncoding::Binary).map_err(|error| crate::SceneError::Io {
        file: dir.display().to_string(),
        source: error,
    })?;
    crate::load_scene(dir, &crate::LoadOptions::default())
}
