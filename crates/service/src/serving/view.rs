//! The view a mask is rendered for: one of the scene's frames (optionally downscaled), or any
//! camera a caller describes with a pose and pinhole intrinsics.

use glam::{Mat3, Mat4, Vec4};
use serde::{Deserialize, Serialize};

use super::ServingError;
use segsplat_engine::RenderCamera;
use segsplat_engine::camera::{DEFAULT_FAR, DEFAULT_NEAR};
use segsplat_method::cameras::SceneCamera;

/// Default cap on a rendered mask's longest side; requests above it are refused rather than
/// allocating a huge render.
pub const DEFAULT_MAX_MASK_SIDE: u32 = 4096;
/// How far a pose's rotation may be from orthonormal (poses come from JSON and other tools).
const ROTATION_TOLERANCE: f32 = 1e-3;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum MaskView {
    /// Frame `index` of the scene (dataset order), scaled so its longest side is at most
    /// `max_side` when given.
    Frame { index: usize, max_side: Option<u32> },
    /// Any camera in the scene's world frame.
    Pose {
        /// Camera-to-world, row-major, OpenCV axes (x right, y down, z forward).
        camera_to_world: [[f64; 4]; 4],
        intrinsics: PinholeIntrinsics,
    },
}

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PinholeIntrinsics {
    /// Focal lengths: positive (`pose_camera` refuses others).
    #[schema(exclusive_minimum = 0.0)]
    pub fx: f64,
    #[schema(exclusive_minimum = 0.0)]
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Image size: 1 to `query.max_mask_side` (4096 by default) per side.
    #[schema(minimum = 1, maximum = 4294967295_u64)]
    pub width: u32,
    #[schema(minimum = 1, maximum = 4294967295_u64)]
    pub height: u32,
}

impl MaskView {
    /// The render camera, checked: the frame exists, sizes are within `max_mask_side`, the pose
    /// is a finite rigid transform and the focal lengths are positive.
    pub fn render_camera(
        &self,
        cameras: &[SceneCamera],
        max_mask_side: u32,
    ) -> Result<RenderCamera, ServingError> {
        let camera = match self {
            MaskView::Frame { index, max_side } => {
                let camera = cameras.get(*index).ok_or(ServingError::FrameOutOfRange {
                    index: *index,
                    frames: cameras.len(),
                })?;
                let longest = camera.width.max(camera.height).max(1);
                let wanted = max_side.unwrap_or(longest).min(max_mask_side);
                if wanted == 0 {
                    return Err(bad_view("max_side must be at least 1"));
                }
                let scale = (wanted as f32 / longest as f32).min(1.0);
                RenderCamera::from_frame(&camera.to_frame(), scale)
                    .map_err(|error| bad_view(error.to_string()))?
            }
            MaskView::Pose {
                camera_to_world,
                intrinsics,
            } => pose_camera(camera_to_world, intrinsics, max_mask_side)?,
        };
        Ok(camera)
    }
}

impl MaskView {
    /// The capture time of the frame a frame view names (dynamic scenes).
    pub fn frame_time(&self, cameras: &[SceneCamera]) -> Option<f32> {
        match self {
            MaskView::Frame { index, .. } => cameras.get(*index).and_then(|camera| camera.time),
            MaskView::Pose { .. } => None,
        }
    }
}

fn bad_view(problem: impl Into<String>) -> ServingError {
    ServingError::BadView(problem.into())
}

fn pose_camera(
    rows: &[[f64; 4]; 4],
    intrinsics: &PinholeIntrinsics,
    max_mask_side: u32,
) -> Result<RenderCamera, ServingError> {
    let PinholeIntrinsics {
        fx,
        fy,
        cx,
        cy,
        width,
        height,
    } = *intrinsics;
    if width == 0 || height == 0 || width.max(height) > max_mask_side {
        return Err(bad_view(format!(
            "image size {width}x{height} must be between 1 and {max_mask_side} pixels per side"
        )));
    }
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(bad_view(format!(
            "focal lengths fx={fx} fy={fy} must be positive"
        )));
    }
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(bad_view("principal point must be finite"));
    }
    if rows.iter().flatten().any(|value| !value.is_finite()) {
        return Err(bad_view("camera_to_world must be finite"));
    }
    if rows[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(bad_view("camera_to_world's last row must be 0 0 0 1"));
    }
    let row = |r: usize| Vec4::from_array(rows[r].map(|value| value as f32));
    let world_from_camera = Mat4::from_cols(row(0), row(1), row(2), row(3)).transpose();
    let rotation = Mat3::from_mat4(world_from_camera);
    let orthonormality = (rotation.transpose() * rotation - Mat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f32, |worst, value| worst.max(value.abs()));
    if orthonormality > ROTATION_TOLERANCE || rotation.determinant() < 0.0 {
        return Err(bad_view(
            "camera_to_world must be a rigid transform (rotation and translation, no scale or \
             reflection)",
        ));
    }
    Ok(RenderCamera {
        width,
        height,
        fx: fx as f32,
        fy: fy as f32,
        cx: cx as f32,
        cy: cy as f32,
        camera_from_world: world_from_camera.inverse(),
        near: DEFAULT_NEAR,
        far: DEFAULT_FAR,
        clamp_to: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> SceneCamera {
        SceneCamera {
            name: "0.png".to_string(),
            width: 200,
            height: 100,
            fx: 100.0,
            fy: 100.0,
            cx: 100.0,
            cy: 50.0,
            camera_to_world: Mat4::IDENTITY.to_cols_array_2d(),
            time: None,
            undistorted_from: None,
        }
    }

    const IDENTITY: [[f64; 4]; 4] = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];

    fn intrinsics() -> PinholeIntrinsics {
        PinholeIntrinsics {
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
            width: 64,
            height: 48,
        }
    }

    #[test]
    fn frames_scale_to_the_requested_side_and_are_range_checked() {
        let cameras = [camera()];
        let view = MaskView::Frame {
            index: 0,
            max_side: Some(100),
        };
        let rendered = view.render_camera(&cameras, 4096).unwrap();
        assert_eq!((rendered.width, rendered.height), (100, 50));
        assert!((rendered.fx - 50.0).abs() < 1e-4);
        let full = MaskView::Frame {
            index: 0,
            max_side: None,
        };
        assert_eq!(full.render_camera(&cameras, 4096).unwrap().width, 200);
        assert_eq!(full.render_camera(&cameras, 64).unwrap().width, 64);
        let missing = MaskView::Frame {
            index: 1,
            max_side: None,
        };
        assert!(matches!(
            missing.render_camera(&cameras, 4096),
            Err(ServingError::FrameOutOfRange {
                index: 1,
                frames: 1
            })
        ));
    }

    #[test]
    fn poses_are_row_major_camera_to_world() {
        let mut rows = IDENTITY;
        rows[0][3] = 2.0; // camera at x = 2
        let view = MaskView::Pose {
            camera_to_world: rows,
            intrinsics: intrinsics(),
        };
        let rendered = view.render_camera(&[], 4096).unwrap();
        assert!(
            rendered
                .position()
                .abs_diff_eq(glam::Vec3::new(2.0, 0.0, 0.0), 1e-6)
        );
    }

    #[test]
    fn bad_poses_and_sizes_are_refused_with_reasons() {
        let refuse = |rows: [[f64; 4]; 4], intrinsics: PinholeIntrinsics, words: &str| {
            let view = MaskView::Pose {
                camera_to_world: rows,
                intrinsics,
            };
            match view.render_camera(&[], 1024) {
                Err(ServingError::BadView(problem)) => {
                    assert!(problem.contains(words), "{problem}")
                }
                other => panic!("expected a bad view, got {other:?}"),
            }
        };
        let mut scaled = IDENTITY;
        scaled[0][0] = 2.0;
        refuse(scaled, intrinsics(), "rigid");
        let mut mirrored = IDENTITY;
        mirrored[2][2] = -1.0;
        refuse(mirrored, intrinsics(), "rigid");
        let mut nan = IDENTITY;
        nan[1][3] = f64::NAN;
        refuse(nan, intrinsics(), "finite");
        let mut projective = IDENTITY;
        projective[3][0] = 0.1;
        refuse(projective, intrinsics(), "last row");
        let huge = PinholeIntrinsics {
            width: 5000,
            ..intrinsics()
        };
        refuse(IDENTITY, huge, "between 1 and 1024");
        let flat = PinholeIntrinsics {
            fx: 0.0,
            ..intrinsics()
        };
        refuse(IDENTITY, flat, "focal");
    }
}
