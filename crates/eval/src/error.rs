//! The one error type of the evaluation module. Every variant names the file or folder it is
//! about, since ground truth comes from hand-made benchmark releases where the path is the fix.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} is not a valid LERF_OVS label file: {source}")]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("cannot decode mask image {path}: {source}")]
    Image {
        path: PathBuf,
        source: image::ImageError,
    },
    /// A label file that parses but says something impossible (bad size, bad frame number).
    #[error("{path}: {reason}")]
    InvalidLabel { path: PathBuf, reason: String },
    #[error(
        "mask {path} is {found_width}x{found_height} but the other masks of view '{view}' are \
         {expected_width}x{expected_height}"
    )]
    MaskSizeMismatch {
        path: PathBuf,
        view: String,
        found_width: u32,
        found_height: u32,
        expected_width: u32,
        expected_height: u32,
    },
    #[error("ground-truth view '{view}' in {path} matches no frame of the scene ({reason})")]
    UnmatchedView {
        path: PathBuf,
        view: String,
        reason: String,
    },
    #[error(
        "ground truth under {path} has two label sets for frame index {frame_index}: '{first}' and '{second}'"
    )]
    DuplicateFrame {
        path: PathBuf,
        frame_index: usize,
        first: String,
        second: String,
    },
    #[error("no ground truth found under {path}: looked for {looked_for}")]
    NotFound { path: PathBuf, looked_for: String },
}

impl EvalError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        EvalError::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn invalid(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        EvalError::InvalidLabel {
            path: path.into(),
            reason: reason.into(),
        }
    }
}
