//! Neu3D / Plenoptic video (DyNeRF) captures, the LLFF-style multi-view video layout:
//!
//! ```text
//! poses_bounds.npy        (cameras, 17) float: a 3x5 pose-and-hwf matrix and near/far bounds
//! cam00.mp4 cam01.mp4 ... one synchronised video per camera, in the rows' order, or
//! cam00/images/0000.png   already-extracted frames (4DGS's preprocessing layout; png or jpg)
//! ```
//!
//! A camera without extracted frames but with a video is decoded once by
//! [`super::video_frames::extract_video_frames`] into `<camera>/images/`, so the stored dataset
//! is self-contained and later loads only read images. `cam00` is Neu3D's held-out test view.
//! Frame `i` of a camera has time `i / (frames per camera - 1)`.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use glam::{Mat3, Mat4, Vec3};

use super::images::{image_size, scaled_size};
use super::npy::read_float_matrix;
use super::video_frames::extract_video_frames;
use super::{
    Frame, FrameSplit, Intrinsics, LoadOptions, Scene, SceneError, SceneFormat, scale_for_max_side,
};

pub const POSES_BOUNDS_FILE: &str = "poses_bounds.npy";
/// Per camera, the folder of frame images (relative to the camera folder).
pub const FRAMES_DIR: &str = "images";
const VIDEO_EXTENSION: &str = "mp4";
const IMAGE_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];
/// Neu3D evaluates on its first camera.
const TEST_CAMERA: &str = "cam00";
/// 15 pose-and-hwf values then near and far.
const ROW_LENGTH: usize = 17;

/// Whether `root` looks like a Neu3D capture.
pub fn is_neu3d(root: &Path) -> bool {
    root.join(POSES_BOUNDS_FILE).is_file()
}

/// One camera of the capture: its name (`cam00`), and its video when there is one.
#[derive(Debug, Clone)]
struct CameraSource {
    name: String,
    video: Option<PathBuf>,
}

/// One `poses_bounds.npy` row.
#[derive(Debug, Clone)]
struct LlffCamera {
    world_from_camera: Mat4,
    intrinsics: Intrinsics,
}

pub fn load_neu3d(root: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let poses = read_float_matrix(root, POSES_BOUNDS_FILE, ROW_LENGTH)?;
    let cameras = discover_cameras(root)?;
    if cameras.is_empty() {
        return Err(SceneError::Inconsistent {
            file: POSES_BOUNDS_FILE.to_string(),
            message: format!(
                "no camera videos (cam00.{VIDEO_EXTENSION}, ...) or frame folders (cam00/{FRAMES_DIR}/) next to it"
            ),
        });
    }
    if poses.rows != cameras.len() {
        return Err(SceneError::Inconsistent {
            file: POSES_BOUNDS_FILE.to_string(),
            message: format!(
                "{} pose rows but {} cameras ({})",
                poses.rows,
                cameras.len(),
                camera_names(&cameras)
            ),
        });
    }
    let llff_cameras = (0..poses.rows)
        .map(|row| llff_camera(poses.row(row), row))
        .collect::<Result<Vec<_>, _>>()?;

    let mut frame_files = Vec::with_capacity(cameras.len());
    for (camera, llff) in cameras.iter().zip(&llff_cameras) {
        let mut files = list_frames(root, &camera.name)?;
        if files.is_empty() {
            let Some(video) = &camera.video else {
                return Err(SceneError::Inconsistent {
                    file: frames_dir(&camera.name).display().to_string(),
                    message: "holds no frame images and there is no video to extract them from"
                        .to_string(),
                });
            };
            let full = (llff.intrinsics.width, llff.intrinsics.height);
            let factor = options
                .video_frames
                .max_side
                .map_or(1.0, |max_side| scale_for_max_side(full.0, full.1, max_side));
            let size = scaled_size(full.0, full.1, factor);
            extract_video_frames(
                root,
                video,
                &frames_dir(&camera.name),
                size,
                &options.video_frames,
            )?;
            files = list_frames(root, &camera.name)?;
        }
        frame_files.push(files);
    }
    let frames_per_camera = common_frame_count(&cameras, &frame_files)?;

    let mut frames = Vec::with_capacity(frames_per_camera * cameras.len());
    for ((camera, llff), files) in cameras.iter().zip(&llff_cameras).zip(&frame_files) {
        let first_path = frames_dir(&camera.name).join(&files[0]);
        let intrinsics = intrinsics_for_images(root, &first_path, &llff.intrinsics)?;
        let split = if camera.name == TEST_CAMERA {
            FrameSplit::Test
        } else {
            FrameSplit::Train
        };
        for (frame_index, file) in files.iter().take(frames_per_camera).enumerate() {
            let time = if frames_per_camera > 1 {
                frame_index as f32 / (frames_per_camera - 1) as f32
            } else {
                0.0
            };
            frames.push(Frame {
                name: format!("{}/{file}", camera.name),
                image_path: frames_dir(&camera.name).join(file),
                intrinsics: intrinsics.clone(),
                world_from_camera: llff.world_from_camera,
                time: Some(time),
                source_id: None,
                split: Some(split),
            });
        }
    }
    Ok(Scene {
        root: root.to_path_buf(),
        format: SceneFormat::Neu3d,
        frames,
        points: None,
        masks: None,
        background: options.background,
    })
}

fn frames_dir(camera: &str) -> PathBuf {
    Path::new(camera).join(FRAMES_DIR)
}

fn camera_names(cameras: &[CameraSource]) -> String {
    cameras
        .iter()
        .map(|camera| camera.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Cameras are the `*.mp4` files and the folders holding an `images/` folder at the root,
/// sorted by name (the order of the pose rows); a camera may have both.
fn discover_cameras(root: &Path) -> Result<Vec<CameraSource>, SceneError> {
    let io_error = |source| SceneError::Io {
        file: root.display().to_string(),
        source,
    };
    let mut cameras: BTreeMap<String, Option<PathBuf>> = BTreeMap::new();
    for entry in fs::read_dir(root).map_err(io_error)? {
        let entry = entry.map_err(io_error)?;
        let file_name = entry.file_name().to_string_lossy().into_owned();
        if file_name.starts_with('.') {
            continue;
        }
        let path = entry.path();
        let is_video = path
            .extension()
            .is_some_and(|extension| extension.eq_ignore_ascii_case(VIDEO_EXTENSION));
        if is_video && path.is_file() {
            let stem = path
                .file_stem()
                .map(|stem| stem.to_string_lossy().into_owned())
                .unwrap_or_default();
            cameras.insert(stem, Some(PathBuf::from(&file_name)));
        } else if path.join(FRAMES_DIR).is_dir() {
            cameras.entry(file_name).or_insert(None);
        }
    }
    Ok(cameras
        .into_iter()
        .map(|(name, video)| CameraSource { name, video })
        .collect())
}

/// Image files in `<camera>/images/`, in frame order: numerically when the stems are numbers
/// (so `10000` follows `9999`), else by name.
fn list_frames(root: &Path, camera: &str) -> Result<Vec<String>, SceneError> {
    let dir = root.join(frames_dir(camera));
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let io_error = |source| SceneError::Io {
        file: frames_dir(camera).display().to_string(),
        source,
    };
    let mut files = Vec::new();
    for entry in fs::read_dir(&dir).map_err(io_error)? {
        let entry = entry.map_err(io_error)?;
        let path = entry.path();
        let is_image = path.extension().is_some_and(|extension| {
            IMAGE_EXTENSIONS
                .iter()
                .any(|known| extension.eq_ignore_ascii_case(known))
        });
        if is_image && path.is_file() {
            files.push(entry.file_name().to_string_lossy().into_owned());
        }
    }
    files.sort_by_key(|file| {
        let stem = Path::new(file)
            .file_stem()
            .map(|stem| stem.to_string_lossy().into_owned())
            .unwrap_or_default();
        (stem.parse::<u64>().ok(), file.clone())
    });
    Ok(files)
}

/// The frame count every camera has. Synchronised captures can differ by a trailing frame
/// or two; the extra frames are left out (times must index the same instants in every camera).
fn common_frame_count(
    cameras: &[CameraSource],
    frame_files: &[Vec<String>],
) -> Result<usize, SceneError> {
    let count = frame_files.iter().map(Vec::len).min().unwrap_or(0);
    if count == 0 {
        return Err(SceneError::Inconsistent {
            file: POSES_BOUNDS_FILE.to_string(),
            message: "a camera has no frames".to_string(),
        });
    }
    for (camera, files) in cameras.iter().zip(frame_files) {
        if files.len() != count {
            tracing::warn!(camera = %camera.name, frames = files.len(), used = count,
                "camera has more frames than the shortest one; the extra frames are not used");
        }
    }
    Ok(count)
}

/// A row's 3x5 matrix holds the camera-to-world rotation with LLFF's camera axes (columns
/// down, right, backwards), the camera centre, and [height, width, focal]. OpenCV's axes are
/// (right, down, forward) = (column 1, column 0, -column 2).
fn llff_camera(row: &[f64], row_index: usize) -> Result<LlffCamera, SceneError> {
    let parse_error = |message: String| SceneError::Parse {
        file: POSES_BOUNDS_FILE.to_string(),
        message: format!("row {row_index}: {message}"),
    };
    let at = |matrix_row: usize, column: usize| row[matrix_row * 5 + column];
    let column = |index: usize| {
        Vec3::new(
            at(0, index) as f32,
            at(1, index) as f32,
            at(2, index) as f32,
        )
    };
    let (down, right, backwards, centre) = (column(0), column(1), column(2), column(3));
    let rotation = Mat3::from_cols(right, down, -backwards);
    if (rotation.determinant() - 1.0).abs() > 1e-2 {
        return Err(parse_error(
            "the rotation columns are not a right-handed orthonormal basis".to_string(),
        ));
    }
    let (height, width, focal) = (at(0, 4), at(1, 4), at(2, 4));
    let side_ok = |side: f64| side >= 1.0 && side <= f64::from(u32::MAX);
    if !side_ok(height) || !side_ok(width) || focal <= 0.0 {
        return Err(parse_error(format!(
            "height {height}, width {width} and focal {focal} must be positive"
        )));
    }
    let (width, height) = (width.round() as u32, height.round() as u32);
    let mut world_from_camera = Mat4::from_mat3(rotation);
    world_from_camera.w_axis = centre.extend(1.0);
    Ok(LlffCamera {
        world_from_camera,
        intrinsics: Intrinsics {
            width,
            height,
            fx: focal,
            fy: focal,
            cx: f64::from(width) / 2.0,
            cy: f64::from(height) / 2.0,
            model: "PINHOLE".to_string(),
            distortion: Vec::new(),
        },
    })
}

/// The camera resized to its frames' size (read from the first frame's header): frames may
/// be extracted smaller than the poses' height and width, but with the same aspect.
fn intrinsics_for_images(
    root: &Path,
    first_frame: &Path,
    full_resolution: &Intrinsics,
) -> Result<Intrinsics, SceneError> {
    let (width, height) = image_size(root, first_frame)?;
    let expected_height =
        f64::from(full_resolution.height) * f64::from(width) / f64::from(full_resolution.width);
    if (expected_height - f64::from(height)).abs() > 1.0 {
        return Err(SceneError::Inconsistent {
            file: first_frame.display().to_string(),
            message: format!(
                "image is {width}x{height} but {POSES_BOUNDS_FILE} says {}x{}: the aspect differs",
                full_resolution.width, full_resolution.height
            ),
        });
    }
    Ok(full_resolution.resized(width, height))
}
