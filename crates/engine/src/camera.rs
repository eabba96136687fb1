//! The pinhole camera the renderer draws through.
//!
//! Conventions (OpenCV, as `scene::Frame`): camera x right, y down, z forward; pixel (u, v) has its
//! centre at (u + 0.5, v + 0.5); a camera-space point projects to `(fx * x / z + cx, fy * y / z + cy)`.

use glam::{Mat4, Vec3};

use segsplat_scene::Frame;

#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error("frame {frame:?}: {problem}")]
    Invalid { frame: String, problem: String },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderCamera {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// World-to-camera rigid transform (OpenCV axes).
    pub camera_from_world: Mat4,
    /// Gaussians whose camera depth is at or below `near` (or at or beyond `far`) are culled.
    pub near: f32,
    pub far: f32,
    /// The image whose field of view the projection's Jacobian is clamped to (x/z and y/z within
    /// [`crate::FRUSTUM_SLACK`] times its half-extent), as `[width, height]`; `None` is this
    /// image. A band of a larger image keeps the whole image's, so it sees the same splats.
    pub clamp_to: Option<[u32; 2]>,
}

/// Near plane used for frames (3DGS / gsplat default).
pub const DEFAULT_NEAR: f32 = 0.01;
/// Far plane used for frames.
pub const DEFAULT_FAR: f32 = 1.0e10;

impl RenderCamera {
    /// The camera of `frame`, with the image scaled by `resolution_scale` (e.g. 0.5 halves width
    /// and height; intrinsics scale with the pixel grid).
    pub fn from_frame(frame: &Frame, resolution_scale: f32) -> Result<Self, CameraError> {
        let invalid = |problem: String| CameraError::Invalid {
            frame: frame.name.clone(),
            problem,
        };
        if !(resolution_scale.is_finite() && resolution_scale > 0.0) {
            return Err(invalid(format!(
                "resolution scale {resolution_scale} must be a positive number"
            )));
        }
        let intrinsics = &frame.intrinsics;
        let width = (intrinsics.width as f32 * resolution_scale).round() as u32;
        let height = (intrinsics.height as f32 * resolution_scale).round() as u32;
        if width == 0 || height == 0 {
            return Err(invalid(format!(
                "image of {}x{} scaled by {resolution_scale} is empty",
                intrinsics.width, intrinsics.height
            )));
        }
        // Scale by the realised pixel grid so rounding keeps the field of view exact.
        let scale_x = width as f64 / intrinsics.width as f64;
        let scale_y = height as f64 / intrinsics.height as f64;
        let determinant = frame.world_from_camera.determinant();
        if !determinant.is_finite() || determinant.abs() < 1e-12 {
            return Err(invalid("world_from_camera is not invertible".to_string()));
        }
        let camera = Self {
            width,
            height,
            fx: (intrinsics.fx * scale_x) as f32,
            fy: (intrinsics.fy * scale_y) as f32,
            cx: (intrinsics.cx * scale_x) as f32,
            cy: (intrinsics.cy * scale_y) as f32,
            camera_from_world: frame.world_from_camera.inverse(),
            near: DEFAULT_NEAR,
            far: DEFAULT_FAR,
            clamp_to: None,
        };
        if !(camera.fx > 0.0 && camera.fy > 0.0) {
            return Err(invalid(format!(
                "focal lengths fx={} fy={} must be positive",
                intrinsics.fx, intrinsics.fy
            )));
        }
        Ok(camera)
    }

    /// Camera centre in world coordinates.
    pub fn position(&self) -> Vec3 {
        self.camera_from_world.inverse().w_axis.truncate()
    }

    /// Number of 16x16 tiles across and down.
    pub fn tile_grid(&self) -> [u32; 2] {
        [
            self.width.div_ceil(crate::TILE_SIZE),
            self.height.div_ceil(crate::TILE_SIZE),
        ]
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The camera of rows `top .. top + rows` of this image: the same rays, with the principal
    /// point moved up by `top`, so each of its pixels sees exactly what that pixel of the whole
    /// image sees. Large images are rendered as such bands to stay within one storage binding.
    pub fn band(&self, top: u32, rows: u32) -> Self {
        Self {
            height: rows,
            cy: self.cy - top as f32,
            clamp_to: Some(self.clamp_size()),
            ..*self
        }
    }

    /// The same camera over an image `divisor` times smaller each way (sides rounded, at least
    /// one pixel): the intrinsics follow the realised pixel grid, so every pixel sees the same
    /// cone of rays as the `divisor` x `divisor` block it stands for, and the field of view (and
    /// with it the Jacobian's clamp) is unchanged. The coarse steps of training render through it.
    pub fn downscaled(&self, divisor: u32) -> Self {
        let divisor = divisor.max(1) as f32;
        let width = ((self.width as f32 / divisor).round() as u32).max(1);
        let height = ((self.height as f32 / divisor).round() as u32).max(1);
        let scale_x = width as f32 / self.width as f32;
        let scale_y = height as f32 / self.height as f32;
        Self {
            width,
            height,
            fx: self.fx * scale_x,
            fy: self.fy * scale_y,
            cx: self.cx * scale_x,
            cy: self.cy * scale_y,
            clamp_to: self.clamp_to.map(|[w, h]| {
                [
                    ((w as f32 * scale_x).round() as u32).max(1),
                    ((h as f32 * scale_y).round() as u32).max(1),
                ]
            }),
            ..*self
        }
    }

    /// The `[width, height]` the Jacobian's clamp follows (see [`Self::clamp_to`]).
    pub fn clamp_size(&self) -> [u32; 2] {
        self.clamp_to.unwrap_or([self.width, self.height])
    }

    /// Where x/z and y/z are clamped in the projection's Jacobian: [`crate::FRUSTUM_SLACK`]
    /// times the tangent of the half field of view of [`Self::clamp_size`]'s image.
    pub fn jacobian_limit(&self) -> [f32; 2] {
        let [width, height] = self.clamp_size();
        [
            crate::FRUSTUM_SLACK * (0.5 * width as f32 / self.fx),
            crate::FRUSTUM_SLACK * (0.5 * height as f32 / self.fy),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use segsplat_scene::Intrinsics;

    fn frame(world_from_camera: Mat4) -> Frame {
        Frame {
            name: "f0".to_string(),
            image_path: "f0.png".into(),
            intrinsics: Intrinsics {
                width: 101,
                height: 60,
                fx: 100.0,
                fy: 90.0,
                cx: 50.5,
                cy: 30.0,
                model: "PINHOLE".to_string(),
                distortion: vec![],
            },
            world_from_camera,
            time: None,
            source_id: None,
            split: None,
        }
    }

    #[test]
    fn from_frame_inverts_pose_and_scales_intrinsics() {
        let world_from_camera = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0));
        let camera = RenderCamera::from_frame(&frame(world_from_camera), 0.5).unwrap();
        assert_eq!((camera.width, camera.height), (51, 30));
        assert!((camera.fx - 100.0 * 51.0 / 101.0).abs() < 1e-4);
        assert!((camera.cy - 15.0).abs() < 1e-5);
        let p = camera
            .camera_from_world
            .transform_point3(Vec3::new(1.0, 2.0, 4.0));
        assert!((p - Vec3::new(0.0, 0.0, 1.0)).length() < 1e-6);
        assert!((camera.position() - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-6);
    }

    #[test]
    fn from_frame_rejects_singular_pose_and_bad_scale() {
        assert!(RenderCamera::from_frame(&frame(Mat4::ZERO), 1.0).is_err());
        let error = RenderCamera::from_frame(&frame(Mat4::IDENTITY), 0.0)
            .unwrap_err()
            .to_string();
        assert!(error.contains("f0") && error.contains("scale"), "{error}");
    }

    #[test]
    fn downscaled_keeps_the_field_of_view() {
        let camera = RenderCamera::from_frame(&frame(Mat4::IDENTITY), 1.0).unwrap();
        let half = camera.downscaled(2);
        assert_eq!((half.width, half.height), (51, 30));
        let [lx, ly] = half.jacobian_limit();
        let [cx, cy] = camera.jacobian_limit();
        assert!((lx - cx).abs() < 1e-5 && (ly - cy).abs() < 1e-5);
        // A point's pixel position scales with the grid.
        let point = Vec3::new(0.3, -0.2, 2.0);
        let project = |c: &RenderCamera| {
            [
                c.fx * point.x / point.z + c.cx,
                c.fy * point.y / point.z + c.cy,
            ]
        };
        let [u, v] = project(&camera);
        let [u2, v2] = project(&half);
        assert!((u2 - u * 51.0 / 101.0).abs() < 1e-4 && (v2 - v * 0.5).abs() < 1e-4);
        assert_eq!(camera.downscaled(1), camera);
        assert_eq!(camera.downscaled(1000).width, 1);
    }
}
