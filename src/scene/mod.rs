//! Datasets: archive unpacking, format detection, parsing and validation into one [`Scene`].
//!
//! Cameras come out in the OpenCV convention (x right, y down, z forward) whatever the source
//! format used (nerfstudio and Blender store OpenGL-convention poses and are converted here).

pub mod archive;
mod types;

pub use archive::{ArchiveError, UnpackLimits, UnpackStats, unpack_archive};
pub use types::*;

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
        "no dataset found: expected COLMAP (sparse/0 or sparse), nerfstudio transforms.json or Blender transforms_train.json{found}"
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
            SceneError::Parse { .. }
            | SceneError::MissingImage { .. }
            | SceneError::UndecodableImage { .. }
            | SceneError::Inconsistent { .. } => InputErrorClass::Invalid,
            SceneError::Io { .. } => InputErrorClass::Internal,
        }
    }
}

/// Detects the format under `root` and parses cameras, frames, sparse points and mask layout.
/// Cheap: images are not decoded (see [`validate_scene`]).
pub fn load_scene(root: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let _ = (root, options);
    Err(SceneError::UnknownFormat {
        found: " (scene loading is not implemented yet)".to_string(),
    })
}

/// Decodes every referenced image and mask and checks sizes and counts; returns the summary the
/// upload endpoint replies with.
pub fn validate_scene(scene: &Scene) -> Result<SceneSummary, SceneError> {
    let _ = scene;
    Err(SceneError::UnknownFormat {
        found: " (scene validation is not implemented yet)".to_string(),
    })
}
