//! `cameras.json`: the views a trained scene was built from, stored with its Gaussians so masks
//! can be rendered "for frame i" without the uploaded dataset (which may be large, remote or
//! deleted).

use glam::Mat4;
use serde::{Deserialize, Serialize};

use segsplat_scene::distortion::undistorted_coefficients;
use segsplat_scene::{Frame, Intrinsics, NamedCoefficient, Scene};

pub const CAMERAS_FILE: &str = "cameras.json";

/// One frame's pinhole camera, in the scene's world frame and units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneCamera {
    /// The frame's name in the dataset (image file name).
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Camera-to-world, row-major 4x4, OpenCV axes (x right, y down, z forward).
    pub camera_to_world: [[f32; 4]; 4],
    /// Normalised capture time, 0..1 over the dataset (dynamic scenes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<f32>,
    /// The distorted camera model this pinhole camera was undistorted from (its images were
    /// remapped as they loaded); absent for pinhole cameras.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub undistorted_from: Option<UndistortedFrom>,
}

/// A frame's original lens, before undistortion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UndistortedFrom {
    /// COLMAP's model name (`OPENCV`, `SIMPLE_RADIAL`, ...).
    pub model: String,
    /// Its distortion coefficients by COLMAP's names, in order.
    pub coefficients: Vec<NamedCoefficient>,
}

impl SceneCamera {
    pub fn from_frame(frame: &Frame) -> Self {
        let intrinsics = &frame.intrinsics;
        Self {
            name: frame.name.clone(),
            width: intrinsics.width,
            height: intrinsics.height,
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            camera_to_world: frame.world_from_camera.transpose().to_cols_array_2d(),
            time: frame.time,
            undistorted_from: undistorted_coefficients(intrinsics).map(|coefficients| {
                UndistortedFrom {
                    model: intrinsics.model.clone(),
                    coefficients,
                }
            }),
        }
    }

    /// The frame this camera describes (no image; pinhole intrinsics).
    pub fn to_frame(&self) -> Frame {
        Frame {
            name: self.name.clone(),
            image_path: self.name.clone().into(),
            intrinsics: Intrinsics {
                width: self.width,
                height: self.height,
                fx: self.fx,
                fy: self.fy,
                cx: self.cx,
                cy: self.cy,
                model: "PINHOLE".to_string(),
                distortion: Vec::new(),
            },
            world_from_camera: Mat4::from_cols_array_2d(&self.camera_to_world).transpose(),
            time: self.time,
            source_id: None,
            split: None,
        }
    }
}

/// Every frame's camera, in the scene's frame order (frame index = position).
pub fn scene_cameras(scene: &Scene) -> Vec<SceneCamera> {
    scene.frames.iter().map(SceneCamera::from_frame).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_survive_the_round_trip() {
        let world_from_camera = Mat4::from_rotation_translation(
            glam::Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1),
            glam::Vec3::new(1.0, -2.0, 3.5),
        );
        let frame = SceneCamera {
            name: "a.png".to_string(),
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 51.0,
            cx: 32.0,
            cy: 24.5,
            camera_to_world: world_from_camera.transpose().to_cols_array_2d(),
            time: Some(0.25),
            undistorted_from: None,
        }
        .to_frame();
        let camera = SceneCamera::from_frame(&frame);
        let json = serde_json::to_string(&vec![camera]).unwrap();
        let back: Vec<SceneCamera> = serde_json::from_str(&json).unwrap();
        let rebuilt = back[0].to_frame();
        assert_eq!(rebuilt.name, "a.png");
        assert_eq!(rebuilt.intrinsics, frame.intrinsics);
        assert_eq!(rebuilt.time, Some(0.25));
        assert!(
            rebuilt
                .world_from_camera
                .abs_diff_eq(world_from_camera, 1e-6)
        );
        // Row-major: each row ends with a translation component.
        assert_eq!(back[0].camera_to_world[1][3], -2.0);
    }

    #[test]
    fn a_distorted_camera_names_the_lens_it_was_undistorted_from() {
        let mut frame = SceneCamera {
            name: "a.png".to_string(),
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
            camera_to_world: Mat4::IDENTITY.to_cols_array_2d(),
            time: None,
            undistorted_from: None,
        }
        .to_frame();
        assert_eq!(SceneCamera::from_frame(&frame).undistorted_from, None);
        frame.intrinsics.model = "OPENCV".to_string();
        frame.intrinsics.distortion = vec![-0.25, 0.05, 0.0, 0.001];
        let camera = SceneCamera::from_frame(&frame);
        let from = camera.undistorted_from.clone().unwrap();
        assert_eq!(from.model, "OPENCV");
        let names: Vec<&str> = from.coefficients.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["k1", "k2", "p1", "p2"]);
        assert_eq!(from.coefficients[0].value, -0.25);
        let json = serde_json::to_value(&camera).unwrap();
        assert_eq!(json["undistorted_from"]["model"], "OPENCV");
        // All-zero OpenCV coefficients change nothing: no undistortion to report.
        frame.intrinsics.distortion = vec![0.0; 4];
        assert_eq!(SceneCamera::from_frame(&frame).undistorted_from, None);
    }
}
