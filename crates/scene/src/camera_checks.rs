//! Poses every consumer can use, checked at upload rather than when a job first renders: a
//! camera-to-world matrix of finite numbers whose rotation part is a rotation (orthonormal,
//! determinant +1) and whose last row is `0 0 0 1`. The renderer inverts the pose and assumes a
//! rigid transform; a scaled, sheared, mirrored or degenerate one would train garbage or fail
//! the job after it was accepted.

use glam::Mat4;

/// How far `Rᵀ R` may be from the identity (per entry): generous for poses stored as rounded
/// decimals, far below any real scale or shear.
const ORTHONORMAL_TOLERANCE: f32 = 1e-2;

/// `Err` says what is wrong with a camera-to-world pose.
pub fn check_pose(world_from_camera: &Mat4) -> Result<(), String> {
    let values = world_from_camera.to_cols_array();
    if let Some(value) = values.iter().find(|value| !value.is_finite()) {
        return Err(format!(
            "world_from_camera holds {value}, not a finite number"
        ));
    }
    let determinant = world_from_camera.determinant();
    if !determinant.is_finite() || determinant.abs() < 1e-12 {
        return Err("world_from_camera is not invertible".to_string());
    }
    let row3 = world_from_camera.row(3);
    if row3.distance(glam::Vec4::W) > 1e-6 {
        return Err(format!(
            "world_from_camera's last row is {:?}, not [0, 0, 0, 1]",
            row3.to_array()
        ));
    }
    let rotation = glam::Mat3::from_mat4(*world_from_camera);
    let gram = rotation.transpose() * rotation;
    let deviation = (gram - glam::Mat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f32, |most, value| most.max(value.abs()));
    if deviation > ORTHONORMAL_TOLERANCE {
        return Err(format!(
            "world_from_camera's rotation is not orthonormal (RᵀR differs from the identity by \
             up to {deviation:.3}): scaled, sheared or degenerate"
        ));
    }
    if rotation.determinant() < 0.0 {
        return Err(
            "world_from_camera's rotation is a reflection (determinant -1), not a rotation"
                .to_string(),
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    #[test]
    fn rigid_poses_pass_and_others_are_named() {
        let rigid = Mat4::from_rotation_translation(
            Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7),
            Vec3::new(1.0, -2.0, 5.0),
        );
        assert_eq!(check_pose(&rigid), Ok(()));
        let cases = [
            (
                Mat4::from_cols_array(&[f32::NAN; 16]),
                "not a finite number",
            ),
            (
                Mat4::from_cols(
                    glam::Vec4::ZERO,
                    glam::Vec4::ZERO,
                    glam::Vec4::ZERO,
                    glam::Vec4::W,
                ),
                "not invertible",
            ),
            (
                rigid * Mat4::from_scale(Vec3::splat(1e-12)),
                "not invertible",
            ),
            (
                rigid * Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0)),
                "not orthonormal",
            ),
            (Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0)), "reflection"),
        ];
        for (pose, expected) in cases {
            let error = check_pose(&pose).unwrap_err();
            assert!(error.contains(expected), "{error}");
        }
    }
}
