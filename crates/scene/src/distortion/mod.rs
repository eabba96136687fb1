//! Lens distortion, undone where the data enters: frames (and user masks) of distorted cameras
//! are remapped to a pinhole camera with the same `fx, fy, cx, cy` and the same size, so the
//! engine, the stored `cameras.json` and every job only ever see pinhole cameras.
//!
//! The models are COLMAP's (the parameter order of [`Intrinsics::distortion`]):
//!
//! - SIMPLE_RADIAL `k`, RADIAL `k1 k2`, OPENCV `k1 k2 p1 p2`, FULL_OPENCV
//!   `k1 k2 p1 p2 k3 k4 k5 k6`: OpenCV's rational radial model with tangential terms,
//!   `x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶) + 2 p1 x y + p2 (r² + 2 x²)`
//!   (and `y_d` with p1 and p2 swapped);
//! - OPENCV_FISHEYE `k1 k2 k3 k4`, RADIAL_FISHEYE `k1 k2`, SIMPLE_RADIAL_FISHEYE `k`: the
//!   equidistant model, `θ = atan r`, `θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`,
//!   `x_d = x θ_d / r`;
//! - FOV `omega`: `r_d = atan(2 r tan(ω / 2)) / ω`.
//!
//! THIN_PRISM_FISHEYE and RAD_TAN_THIN_PRISM_FISHEYE are refused.
//!
//! Undistortion needs the inverse map: for each output (pinhole) pixel, its normalised
//! coordinate is distorted (the closed-form direction) and the input is sampled there, bilinearly
//! for images and at the nearest pixel for instance masks, so ids stay ids. Pixel centres are at
//! `i + 0.5` (COLMAP's convention, and the renderer's). Output pixels whose source lies outside
//! the input (pincushion lenses, at the corners) take the nearest edge pixel. Single points
//! (COLMAP keypoints) are undistorted with Newton's method.

mod lens;
mod remap;
#[cfg(test)]
mod tests;

pub use lens::{Lens, UNDISTORTED_MODELS, distort_pixel, undistort_pixel};
pub use remap::{RemapStats, undistort_mask, undistort_rgb};

use super::{Intrinsics, NamedCoefficient, Scene, UndistortedLens};

/// The scene's distorted cameras, one entry per model, coefficients and size (in first-frame
/// order), with how many frames use each; frames whose lens is a pinhole (no model with
/// distortion, or all coefficients zero) are left out, as are invalid ones (validation refuses
/// them).
pub fn undistorted_lenses(scene: &Scene) -> Vec<UndistortedLens> {
    let mut lenses: Vec<UndistortedLens> = Vec::new();
    for frame in &scene.frames {
        let intrinsics = &frame.intrinsics;
        let Some(coefficients) = undistorted_coefficients(intrinsics) else {
            continue;
        };
        let size = [intrinsics.width, intrinsics.height];
        match lenses.iter_mut().find(|lens| {
            lens.model == intrinsics.model && lens.size == size && lens.coefficients == coefficients
        }) {
            Some(lens) => lens.frame_count += 1,
            None => lenses.push(UndistortedLens {
                model: intrinsics.model.clone(),
                coefficients,
                frame_count: 1,
                size,
                undistorted_size: size,
            }),
        }
    }
    lenses
}

/// The named distortion coefficients of a camera whose frames are undistorted; `None` for a
/// pinhole lens (no distortion, or all coefficients zero) and for an invalid one.
pub fn undistorted_coefficients(intrinsics: &Intrinsics) -> Option<Vec<NamedCoefficient>> {
    match Lens::from_intrinsics(intrinsics) {
        Ok(lens) if !lens.is_pinhole() => {}
        _ => return None,
    }
    Some(
        intrinsics
            .distortion
            .iter()
            .enumerate()
            .map(|(index, value)| NamedCoefficient {
                name: parameter_name(&intrinsics.model, index).to_string(),
                value: *value,
            })
            .collect(),
    )
}

/// One line for logs and job events: `OPENCV k1=-0.3 k2=0.1 p1=0 p2=0, 640x480 -> 640x480 (23 frames)`.
pub fn describe_lens(lens: &UndistortedLens) -> String {
    let coefficients: Vec<String> = lens
        .coefficients
        .iter()
        .map(|c| format!("{}={}", c.name, c.value))
        .collect();
    format!(
        "{} {}, {}x{} undistorted to {}x{} pinhole ({} frame{})",
        lens.model,
        coefficients.join(" "),
        lens.size[0],
        lens.size[1],
        lens.undistorted_size[0],
        lens.undistorted_size[1],
        lens.frame_count,
        if lens.frame_count == 1 { "" } else { "s" }
    )
}

fn parameter_name(model: &str, index: usize) -> &'static str {
    let names: &[&'static str] = match model {
        "SIMPLE_RADIAL" | "SIMPLE_RADIAL_FISHEYE" => &["k"],
        "RADIAL" | "RADIAL_FISHEYE" => &["k1", "k2"],
        "OPENCV" => &["k1", "k2", "p1", "p2"],
        "OPENCV_FISHEYE" => &["k1", "k2", "k3", "k4"],
        "FULL_OPENCV" => &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
        "FOV" => &["omega"],
        _ => &[],
    };
    names.get(index).copied().unwrap_or("?")
}
