//! The dataset model every format parses into.

use std::path::PathBuf;

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneFormat {
    Colmap,
    Nerfstudio,
    /// Blender NeRF, including D-NeRF (whose frames carry a `time`).
    Blender,
    /// Nerfies and HyperNeRF captures (`dataset.json`, `camera/<id>.json`, `rgb/<scale>x/`).
    Nerfies,
    /// Neu3D / Plenoptic video (`poses_bounds.npy`, one video or frame folder per camera).
    Neu3d,
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

impl Intrinsics {
    /// The intrinsics of this camera after resizing its image by `factor` (0.5 halves it).
    ///
    /// Width and height are rounded (at least 1 pixel) exactly as [`crate::scaled_size`]
    /// does for images, and the focal lengths and principal point are scaled by the per-axis
    /// ratios actually achieved, so the result matches the resized image to the pixel.
    pub fn scaled(&self, factor: f64) -> Intrinsics {
        let (width, height) = crate::scaled_size(self.width, self.height, factor);
        self.resized(width, height)
    }

    /// The intrinsics of this camera for its image resized to exactly `width` x `height`: focal
    /// lengths and principal point scale by the per-axis ratios (datasets that ship downscaled
    /// images give full-resolution cameras).
    pub fn resized(&self, width: u32, height: u32) -> Intrinsics {
        let x_ratio = f64::from(width) / f64::from(self.width.max(1));
        let y_ratio = f64::from(height) / f64::from(self.height.max(1));
        Intrinsics {
            width,
            height,
            fx: self.fx * x_ratio,
            fy: self.fy * y_ratio,
            cx: self.cx * x_ratio,
            cy: self.cy * y_ratio,
            model: self.model.clone(),
            distortion: self.distortion.clone(),
        }
    }
}

/// Which evaluation split a frame belongs to, when the source says (Blender NeRF files).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameSplit {
    Train,
    Val,
    Test,
}

/// One posed image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    /// Stable name (file name relative to the image folder), used for ordering and mask lookup.
    pub name: String,
    /// Path of the image relative to the scene root.
    pub image_path: PathBuf,
    pub intrinsics: Intrinsics,
    /// Camera-to-world, OpenCV convention (x right, y down, z forward).
    pub world_from_camera: Mat4,
    /// Capture time of dynamic scenes, normalised to [0, 1] over the dataset (D-NeRF `time` as
    /// given, Nerfies `time_id` over its maximum, Neu3D frame index over the last index);
    /// `None` for static scenes.
    pub time: Option<f32>,
    /// COLMAP image id, when the source has one (links 2D-3D tracks).
    pub source_id: Option<u32>,
    /// Train/val/test split when the source defines one; `None` means "use for training".
    pub split: Option<FrameSplit>,
}

/// Sparse reconstruction points, with their COLMAP tracks when known.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SparsePoints {
    pub positions: Vec<Vec3>,
    /// 0..1 RGB as stored by the source (sRGB-encoded values divided by 255, as 3DGS uses them).
    pub colors: Vec<Vec3>,
    /// Per point: the frames (indices into `Scene::frames`) that observe it, and the 2D pixel
    /// position there. Empty per point when the source has no tracks.
    pub tracks: Vec<Vec<TrackObservation>>,
}

impl SparsePoints {
    /// Keeps the points whose position `keep` accepts, with their colours and tracks.
    pub fn retain(&mut self, mut keep: impl FnMut(Vec3) -> bool) {
        let kept: Vec<bool> = self.positions.iter().map(|&p| keep(p)).collect();
        let mut flags = kept.iter();
        self.positions.retain(|_| *flags.next().unwrap_or(&true));
        let mut flags = kept.iter();
        self.colors.retain(|_| *flags.next().unwrap_or(&true));
        let mut flags = kept.iter();
        self.tracks.retain(|_| *flags.next().unwrap_or(&true));
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackObservation {
    pub frame_index: u32,
    pub pixel: [f32; 2],
}

/// Where user-provided instance-id masks are for each level (`masks/{level}/<image stem>.png`).
/// When only some levels are given, a missing level uses the nearest given one (the finer one on a
/// tie), so one given level serves all three; see [`MaskLayout::source_level`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MaskLayout {
    /// Per level (small, middle, large): per frame, the mask path relative to the scene root.
    /// `None` for levels the user did not give.
    pub paths: [Option<Vec<PathBuf>>; 3],
}

impl MaskLayout {
    /// Levels for which masks were given, finest first.
    pub fn given_levels(&self) -> Vec<Level> {
        Level::ALL
            .into_iter()
            .filter(|level| self.paths[level.index()].is_some())
            .collect()
    }

    /// The given level whose masks serve `level`: itself when given, else the nearest given level,
    /// preferring the finer one when two are equally near. `None` when no level was given.
    pub fn source_level(&self, level: Level) -> Option<Level> {
        let given = self.given_levels();
        given.into_iter().min_by_key(|candidate| {
            let distance = candidate.index().abs_diff(level.index());
            (distance, candidate.index())
        })
    }

    /// Mask path (relative to the scene root) serving `level` for frame `frame_index`.
    pub fn path_for(&self, level: Level, frame_index: usize) -> Option<&PathBuf> {
        let source = self.source_level(level)?;
        self.paths[source.index()].as_ref()?.get(frame_index)
    }
}

/// One decoded instance-id mask: row-major ids, 0 = no object.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InstanceMask {
    pub width: u32,
    pub height: u32,
    pub ids: Vec<u32>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    pub root: PathBuf,
    pub format: SceneFormat,
    /// Frames in capture order (sorted by name unless the format orders them).
    pub frames: Vec<Frame>,
    pub points: Option<SparsePoints>,
    pub masks: Option<MaskLayout>,
    /// Background composited under RGBA images (0..1 RGB in the images' own sRGB encoding).
    pub background: [f32; 3],
}

impl Scene {
    /// Whether any frame has a capture time (D-NeRF, Nerfies/HyperNeRF, Neu3D).
    pub fn is_dynamic(&self) -> bool {
        self.frames.iter().any(|frame| frame.time.is_some())
    }

    /// The distinct capture times, ascending (empty for static scenes).
    pub fn frame_times(&self) -> Vec<f32> {
        let mut times: Vec<f32> = self.frames.iter().filter_map(|frame| frame.time).collect();
        times.sort_by(f32::total_cmp);
        times.dedup();
        times
    }
}

/// Options for [`crate::load_scene`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct LoadOptions {
    /// Background for RGBA (Blender) images, 0..1 sRGB-encoded RGB; white by default.
    pub background: [f32; 3],
    /// Nerfies/HyperNeRF: which `rgb/<scale>x/` folder to read (e.g. 2 for `rgb/2x`); `None`
    /// takes the smallest scale present (the highest resolution; the engine downscales itself).
    pub nerfies_scale: Option<u32>,
    /// Neu3D: how videos are turned into frame images when a camera has no extracted frames.
    pub video_frames: VideoFrameOptions,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            background: [1.0, 1.0, 1.0],
            nerfies_scale: None,
            video_frames: VideoFrameOptions::default(),
        }
    }
}

/// Frame extraction from Neu3D camera videos (done once, with the `ffmpeg` program, into
/// `<camera>/images/` next to the video).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VideoFrameOptions {
    /// Keep every `frame_step`-th video frame (1 keeps all).
    pub frame_step: u32,
    /// At most this many frames per camera (after stepping); `None` keeps all.
    pub max_frames: Option<u32>,
    /// Longest side of the extracted images; `None` keeps the size `poses_bounds.npy` gives.
    /// 1352 by default: half of Neu3D's 2704x2028, as 4DGS and Deformable-3DGS train on.
    pub max_side: Option<u32>,
    /// The ffmpeg program, looked up on `PATH` unless a path is given.
    pub ffmpeg: PathBuf,
}

impl Default for VideoFrameOptions {
    fn default() -> Self {
        Self {
            frame_step: 1,
            max_frames: None,
            max_side: Some(1352),
            ffmpeg: PathBuf::from("ffmpeg"),
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
    /// Distinct capture times; 0 for static scenes (absent in summaries stored before dynamic
    /// formats existed, which were all static).
    #[serde(default)]
    pub time_count: u32,
    /// Files in the upload the dataset does not use ([`super::used_files`]); not stored.
    #[serde(default)]
    pub ignored_file_count: u64,
    /// The first of them (at most [`IGNORED_FILES_LISTED`]), relative to the dataset.
    #[serde(default)]
    pub ignored_files: Vec<String>,
    /// Camera models with lens distortion whose frames (and masks) are undistorted to pinhole
    /// cameras where they are loaded ([`crate::distortion`]); empty when every camera is
    /// pinhole (and in summaries stored before this was reported).
    #[serde(default)]
    pub undistorted: Vec<UndistortedLens>,
}

/// A distorted camera model of an upload and what its frames become: pinhole cameras with the
/// same `fx, fy, cx, cy` and the same size.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct UndistortedLens {
    /// The model as the source named it (COLMAP's: `OPENCV`, `SIMPLE_RADIAL`, ...).
    pub model: String,
    /// Its distortion coefficients by COLMAP's names (`k1`, `k2`, `p1`, `p2`, `omega`, ...), in
    /// COLMAP's order.
    pub coefficients: Vec<NamedCoefficient>,
    /// Frames with this camera.
    pub frame_count: u32,
    /// Their images' size, [width, height].
    pub size: [u32; 2],
    /// The size of the undistorted images (the pinhole camera keeps the size).
    pub undistorted_size: [u32; 2],
}

/// One distortion coefficient.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct NamedCoefficient {
    pub name: String,
    pub value: f64,
}

/// How many ignored files a summary names.
pub const IGNORED_FILES_LISTED: usize = 20;
