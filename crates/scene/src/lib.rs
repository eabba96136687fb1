//! Datasets: archive unpacking, format detection, parsing and validation into one [`Scene`].
//!
//! Cameras come out in the OpenCV convention (x right, y down, z forward) whatever the source
//! format used (nerfstudio and Blender store OpenGL-convention poses, Neu3D LLFF's
//! down-right-back axes; they are converted here). Dynamic formats (D-NeRF, Nerfies/HyperNeRF,
//! Neu3D) give every frame a capture time normalised to [0, 1]. Lens distortion is undone where
//! images and masks are loaded ([`distortion`]): callers see pinhole frames with the same
//! `fx, fy, cx, cy` whatever the source's camera model.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

pub mod archive;
pub mod blender;
mod camera_checks;
pub mod colmap;
mod dataset_path;
mod dataset_root;
pub mod distortion;
#[doc(hidden)]
pub mod fuzz_entry;
pub mod id_runs;
mod images;
mod jpeg_scaled;
pub mod masks;
pub mod nerfies;
pub mod nerfstudio;
pub mod neu3d;
mod npy;
pub mod pixel_limits;
pub mod point_ply;
pub mod sequence;
pub mod synthetic;
pub mod synthetic_dynamic;
pub mod synthetic_dynamic_formats;
mod transforms_json;
mod types;
pub mod used_files;
mod validate;
pub mod video_frames;

pub use archive::{ArchiveError, UnpackLimits, UnpackStats, unpack_archive};
pub use dataset_root::resolve_dataset_root;
pub use images::{load_frame_rgb, scale_for_max_side, scaled_size};
pub use masks::load_instance_mask;
pub use pixel_limits::PixelLimits;
pub use types::*;
pub use validate::{validate_scene, validate_scene_within};

use std::path::Path;

/// How a caller should treat a rejected input; the API maps these to HTTP statuses
/// (400, 413, 415, 422) without this module knowing about HTTP.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputErrorClass {
    /// The bytes are broken: truncated or corrupt archive, unreadable structure (400).
    Malformed,
    /// Over a configured size or count limit (413).
    TooLarge,
    /// Not an archive kind or dataset format we read (415).
    UnsupportedFormat,
    /// Well-formed but inconsistent: missing or undecodable image, counts that do not match (422).
    Invalid,
    /// Our fault or the machine's (disk full, permissions) (500).
    Internal,
}

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(
        "no dataset found: expected COLMAP (sparse/0 or sparse), nerfstudio transforms.json, Blender/D-NeRF transforms_train.json, Nerfies/HyperNeRF dataset.json with camera/, or Neu3D poses_bounds.npy{found}"
    )]
    UnknownFormat { found: String },
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
    #[error("{file}: referenced image is missing")]
    MissingImage { file: String },
    #[error("{file}: image cannot be decoded: {message}")]
    UndecodableImage { file: String, message: String },
    #[error("{file}: {message}")]
    Inconsistent { file: String, message: String },
    /// Over a configured bound on decoded image size ([`pixel_limits`]).
    #[error("{file}: {message}")]
    TooManyPixels { file: String, message: String },
    #[error("{file}: video cannot be decoded: {message}")]
    UndecodableVideo { file: String, message: String },
    /// The server lacks the video decoder program (a deployment problem, not the upload's).
    #[error(
        "the video decoder {program:?} is not installed (needed to extract frames from videos)"
    )]
    VideoDecoderMissing { program: String },
    #[error("{file}: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
}

impl SceneError {
    pub fn class(&self) -> InputErrorClass {
        match self {
            SceneError::UnknownFormat { .. } => InputErrorClass::UnsupportedFormat,
            SceneError::TooManyPixels { .. } => InputErrorClass::TooLarge,
            SceneError::Parse { .. }
            | SceneError::MissingImage { .. }
            | SceneError::UndecodableImage { .. }
            | SceneError::Inconsistent { .. }
            | SceneError::UndecodableVideo { .. } => InputErrorClass::Invalid,
            SceneError::Io { .. } | SceneError::VideoDecoderMissing { .. } => {
                InputErrorClass::Internal
            }
        }
    }
}

/// Detects the format under `root` and parses cameras, frames, sparse points and mask layout.
/// Cheap: images are not decoded (see [`validate_scene`]), with one exception: Neu3D cameras
/// given only as videos are decoded once into frame images inside `root` (see [`neu3d`]).
///
/// Formats are tried in this order: COLMAP (`sparse/0` or `sparse`), nerfstudio
/// (`transforms.json`), Blender NeRF / D-NeRF (`transforms_train.json`), Nerfies/HyperNeRF
/// (`dataset.json` and `camera/`), Neu3D (`poses_bounds.npy`). When none is at `root` itself but
/// `root` holds exactly one folder (ignoring hidden entries and `__MACOSX`), that folder is the
/// dataset root: users often archive the dataset folder itself. [`Scene::root`] is the folder
/// actually used.
pub fn load_scene(root: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let dataset_root = resolve_dataset_root(root)?;
    let mut scene = if let Some(location) = colmap::find_model(&dataset_root) {
        colmap::load_colmap(&dataset_root, &location, options)?
    } else if dataset_root.join(nerfstudio::TRANSFORMS_FILE).is_file() {
        nerfstudio::load_nerfstudio(&dataset_root, options)?
    } else if dataset_root.join(blender::TRAIN_TRANSFORMS_FILE).is_file() {
        blender::load_blender(&dataset_root, options)?
    } else if nerfies::is_nerfies(&dataset_root) {
        nerfies::load_nerfies(&dataset_root, options)?
    } else if neu3d::is_neu3d(&dataset_root) {
        neu3d::load_neu3d(&dataset_root, options)?
    } else {
        return Err(SceneError::UnknownFormat {
            found: dataset_root::describe_contents(&dataset_root),
        });
    };
    check_lenses(&scene)?;
    scene.masks = masks::discover_masks(&dataset_root, &scene.frames)?;
    Ok(scene)
}

/// Every frame's camera must be one whose distortion [`distortion`] undoes (the COLMAP and
/// nerfstudio loaders check this themselves with their own file names; this catches the rest),
/// with a rigid pose ([`camera_checks`]).
fn check_lenses(scene: &Scene) -> Result<(), SceneError> {
    for frame in &scene.frames {
        distortion::Lens::from_intrinsics(&frame.intrinsics)
            .and_then(|_| camera_checks::check_pose(&frame.world_from_camera))
            .map_err(|message| SceneError::Parse {
                file: frame.image_path.display().to_string(),
                message: format!("camera of frame {}: {message}", frame.name),
            })?;
    }
    Ok(())
}
