//! COLMAP's sparse model as stored on disk, before conversion to a [`crate::Scene`].

use std::collections::BTreeMap;

use super::camera_models::CameraModel;

#[derive(Debug, Clone, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    pub model: CameraModel,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
}

/// A registered image: world-to-camera rotation (`qvec` = w, x, y, z) and translation, plus its
/// 2D keypoints with the id of the 3D point each observes (-1 for none).
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    pub qvec: [f64; 4],
    pub tvec: [f64; 3],
    pub camera_id: u32,
    pub name: String,
    pub points2d: Vec<ColmapKeypoint>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColmapKeypoint {
    pub xy: [f64; 2],
    pub point3d_id: i64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ColmapPoint {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    pub error: f64,
    pub track: Vec<ColmapTrackElement>,
}

/// One observation of a 3D point: the image and the index of the keypoint in that image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColmapTrackElement {
    pub image_id: u32,
    pub point2d_index: u32,
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct ColmapModel {
    pub cameras: BTreeMap<u32, ColmapCamera>,
    pub images: Vec<ColmapImage>,
    pub points: Vec<ColmapPoint>,
}
