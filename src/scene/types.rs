//! The dataset model every format parses into.

use std::path::PathBuf;

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneFormat {
    Colmap,
    Nerfstudio,
    Blender,
}

/// Object granularity levels; also the mask folder names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    Small,
    Middle,
    Large,
}

impl Level {
    pub const ALL: [Level; 3] = [Level::Small, Level::Middle, Level::Large];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Level::Small => "small",
            Level::Middle => "middle",
            Level::Large => "large",
        }
    }
}

/// Lens model as the source stored it. The renderer is pinhole; distortion parameters are kept
/// so callers can warn or undistort.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// COLMAP model name (e.g. "PINHOLE", "OPENCV") or "PINHOLE" for formats without one.
    pub model: String,
    /// Extra parameters after the focal lengths and principal point (distortion), as stored.
    pub distortion: Vec<f64>,
}

/// One posed image.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Frame {
    /// Stable name (file name relative to the image folder), used for ordering and mask lookup.
    pub name: String,
    /// Path of the image relative to the scene root.
    pub image_path: PathBuf,
    pub intrinsics: Intrinsics,
    /// Camera-to-world, OpenCV convention (x right, y down, z forward).
    pub world_from_camera: Mat4,
    /// Capture time in seconds for dynamic scenes.
    pub time: Option<f32>,
    /// COLMAP image id, when the source has one (links 2D-3D tracks).
    pub source_id: Option<u32>,
}

/// Sparse reconstruction points, with their COLMAP tracks when known.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SparsePoints {
    pub positions: Vec<Vec3>,
    /// Linear 0..1 RGB.
    pub colors: Vec<Vec3>,
    /// Per point: the frames (indices into `Scene::frames`) that observe it, and the 2D pixel
    /// position there. Empty per point when the source has no tracks.
    pub tracks: Vec<Vec<TrackObservation>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackObservation {
    pub frame_index: u32,
    pub pixel: [f32; 2],
}

/// Where user-provided instance-id masks are for each level (`masks/{level}/<image stem>.png`).
/// When only one level is given it serves all three.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MaskLayout {
    /// Per level (small, middle, large): per frame, the mask path relative to the scene root.
    pub paths: [Option<Vec<PathBuf>>; 3],
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Scene {
    pub root: PathBuf,
    pub format: SceneFormat,
    /// Frames in capture order (sorted by name unless the format orders them).
    pub frames: Vec<Frame>,
    pub points: Option<SparsePoints>,
    pub masks: Option<MaskLayout>,
    /// Background composited under RGBA images (linear 0..1 RGB).
    pub background: [f32; 3],
}

/// Options for [`crate::scene::load_scene`].
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LoadOptions {
    /// Background for RGBA (Blender) images, 0..1 RGB; white by default.
    pub background: [f32; 3],
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            background: [1.0, 1.0, 1.0],
        }
    }
}

/// What an upload reports back.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SceneSummary {
    pub format: SceneFormat,
    pub frame_count: u32,
    /// Distinct image sizes, [width, height].
    pub resolutions: Vec<[u32; 2]>,
    pub sparse_point_count: u64,
    /// Levels for which user masks were given.
    pub mask_levels: Vec<Level>,
}
