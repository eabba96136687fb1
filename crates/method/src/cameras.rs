//! `cameras.json`: the views a trained scene was built from, stored with its Gaussians so masks
//! can be rendered "for frame i" without the uploaded dataset (which may be large, remote or
//! deleted).

use glam::Mat4;
use serde::{Deserialize, Serialize};

use segsplat_scene::{Frame, Intrinsics, Scene};

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
}
