//! What the format tests share: pose comparison and the pinhole projection the engine uses.

use glam::{Mat4, Vec3};
use segsplat_scene::Frame;

pub(crate) fn assert_pose_close(actual: Mat4, expected: Mat4, label: &str) {
    let largest = (actual - expected)
        .abs()
        .to_cols_array()
        .into_iter()
        .fold(0.0f32, f32::max);
    assert!(
        largest < 1e-4,
        "{label}: pose differs by {largest}\n{actual}\n{expected}"
    );
}

/// Where a frame sees `world_point`, by the pinhole model the engine uses.
pub(crate) fn project(frame: &Frame, world_point: Vec3) -> [f64; 2] {
    let camera_point = frame
        .world_from_camera
        .inverse()
        .transform_point3(world_point);
    assert!(
        camera_point.z > 0.0,
        "{world_point} is behind {}",
        frame.name
    );
    let intrinsics = &frame.intrinsics;
    [
        intrinsics.fx * f64::from(camera_point.x / camera_point.z) + intrinsics.cx,
        intrinsics.fy * f64::from(camera_point.y / camera_point.z) + intrinsics.cy,
    ]
}
