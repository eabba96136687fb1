//! Serving trained scenes: load a finished job's Gaussians, labels and cameras, keep them on the
//! GPU in an LRU cache, render object masks for a frame or any pose, encode them as PNG or COCO
//! RLE, and export single objects as PLY. The REST and gRPC handlers and the CLI share it.

pub mod mask_encoding;
pub mod object_export;
pub mod scene_cache;
pub mod scene_motion;
pub mod trained_scene;
pub mod view;

pub use mask_encoding::{EncodedMask, EncodedMaskData, MaskFormat, encode_mask, mask_png};
pub use object_export::{SplatFormat, encode_splats, object_file, object_model};
pub use scene_cache::{CacheStats, GpuRelease, LoadedScene, ObjectMasks, SceneCache};
pub use segsplat_method::cameras::{CAMERAS_FILE, SceneCamera, scene_cameras};
pub use segsplat_method::scene_files::{LABELS_FILE, SCENE_FILE};
pub use trained_scene::{TrainedScene, parse_cameras};
pub use view::{DEFAULT_MAX_MASK_SIDE, MaskView, PinholeIntrinsics};

use segsplat_scene::Level;

#[derive(Debug, thiserror::Error)]
pub enum ServingError {
    #[error("{file} is missing from {location}; was the scene trained by this version?")]
    MissingFile { file: String, location: String },
    #[error("{file} is unreadable: {problem}")]
    Corrupt { file: String, problem: String },
    #[error("reading the trained scene failed: {0}")]
    Storage(String),
    #[error("frame {index} does not exist (the scene has {frames} frames)")]
    FrameOutOfRange { index: usize, frames: usize },
    #[error("view: {0}")]
    BadView(String),
    #[error("the scene has no {} object {object_id}", level.name())]
    NoSuchObject { level: Level, object_id: u32 },
    #[error("no GPU for rendering masks: {0}")]
    NoGpu(String),
    #[error("rendering failed: {0}")]
    Gpu(String),
    #[error("encoding failed: {0}")]
    Encoding(String),
}
