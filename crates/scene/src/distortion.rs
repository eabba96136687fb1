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

use image::Rgb32FImage;
use rayon::prelude::*;

use super::{InstanceMask, Intrinsics, NamedCoefficient, Scene, UndistortedLens};

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

/// A camera's lens distortion in normalised image coordinates (`x = X / Z`, `y = Y / Z`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lens {
    /// No distortion.
    Pinhole,
    /// OpenCV's rational model: `radial` = k1..k6 (k4..k6 in the denominator), `tangential` =
    /// p1, p2.
    OpenCv {
        radial: [f64; 6],
        tangential: [f64; 2],
    },
    /// The equidistant fisheye model with k1..k4 (on θ², θ⁴, θ⁶, θ⁸).
    Fisheye { k: [f64; 4] },
    /// COLMAP's FOV model (Devernay and Faugeras) with field of view `omega` (radians).
    Fov { omega: f64 },
}

/// Camera models whose distortion this module undoes, as named in errors.
pub const UNDISTORTED_MODELS: &str = "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, \
     FULL_OPENCV, OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE, FOV";

impl Lens {
    /// The lens of `intrinsics` (its model name and COLMAP-ordered parameters). Errors say what is
    /// wrong (unknown or unsupported model, wrong parameter count, a parameter that is not a
    /// finite number, a focal length that is not positive); callers add the file and camera.
    pub fn from_intrinsics(intrinsics: &Intrinsics) -> Result<Lens, String> {
        let model = intrinsics.model.as_str();
        for (name, value) in [
            ("fx", intrinsics.fx),
            ("fy", intrinsics.fy),
            ("cx", intrinsics.cx),
            ("cy", intrinsics.cy),
        ] {
            if !value.is_finite() {
                return Err(format!(
                    "{model} camera: {name} is {value}, not a finite number"
                ));
            }
        }
        if intrinsics.fx <= 0.0 || intrinsics.fy <= 0.0 {
            return Err(format!(
                "{model} camera: focal lengths must be positive, got fx {} and fy {}",
                intrinsics.fx, intrinsics.fy
            ));
        }
        let params = intrinsics.distortion.as_slice();
        if let Some((index, value)) = params.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(format!(
                "{model} camera: distortion parameter {} ({}) is {value}, not a finite number",
                index + 1,
                parameter_name(model, index)
            ));
        }
        let expected = match model {
            "SIMPLE_PINHOLE" | "PINHOLE" => 0,
            "SIMPLE_RADIAL" | "SIMPLE_RADIAL_FISHEYE" | "FOV" => 1,
            "RADIAL" | "RADIAL_FISHEYE" => 2,
            "OPENCV" | "OPENCV_FISHEYE" => 4,
            "FULL_OPENCV" => 8,
            "THIN_PRISM_FISHEYE" | "RAD_TAN_THIN_PRISM_FISHEYE" => {
                return Err(format!(
                    "camera model {model} cannot be undistorted (supported: {UNDISTORTED_MODELS}); \
                     undistort the images first, e.g. with colmap image_undistorter"
                ));
            }
            other => {
                return Err(format!(
                    "unknown camera model {other:?} (supported: {UNDISTORTED_MODELS})"
                ));
            }
        };
        if params.len() != expected {
            return Err(format!(
                "{model} camera: expected {expected} distortion parameters, found {}",
                params.len()
            ));
        }
        let p = |index: usize| params[index];
        let lens = match model {
            "SIMPLE_PINHOLE" | "PINHOLE" => Lens::Pinhole,
            "SIMPLE_RADIAL" => Lens::open_cv([p(0), 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0]),
            "RADIAL" => Lens::open_cv([p(0), p(1), 0.0, 0.0, 0.0, 0.0], [0.0, 0.0]),
            "OPENCV" => Lens::open_cv([p(0), p(1), 0.0, 0.0, 0.0, 0.0], [p(2), p(3)]),
            "FULL_OPENCV" => Lens::open_cv([p(0), p(1), p(4), p(5), p(6), p(7)], [p(2), p(3)]),
            "OPENCV_FISHEYE" => Lens::Fisheye {
                k: [p(0), p(1), p(2), p(3)],
            },
            "SIMPLE_RADIAL_FISHEYE" => Lens::Fisheye {
                k: [p(0), 0.0, 0.0, 0.0],
            },
            "RADIAL_FISHEYE" => Lens::Fisheye {
                k: [p(0), p(1), 0.0, 0.0],
            },
            _ => {
                // FOV (the only other model with an expected count above).
                if p(0) == 0.0 {
                    Lens::Pinhole
                } else {
                    Lens::Fov { omega: p(0) }
                }
            }
        };
        Ok(lens)
    }

    fn open_cv(radial: [f64; 6], tangential: [f64; 2]) -> Lens {
        Lens::OpenCv { radial, tangential }
    }

    /// Whether the lens leaves every point where it is (no remapping needed): no distortion, or
    /// the OpenCV family with all coefficients zero. Fisheye models never are: the equidistant
    /// projection bends rays even with zero coefficients (`θ_d = θ`, not `tan θ`).
    pub fn is_pinhole(&self) -> bool {
        match self {
            Lens::Pinhole => true,
            Lens::OpenCv { radial, tangential } => {
                radial.iter().chain(tangential).all(|value| *value == 0.0)
            }
            Lens::Fisheye { .. } | Lens::Fov { .. } => false,
        }
    }

    /// Distorts a normalised image coordinate: where a ray through `(x, y, 1)` lands on the
    /// normalised plane of the distorted camera.
    pub fn distort(&self, [x, y]: [f64; 2]) -> [f64; 2] {
        match *self {
            Lens::Pinhole => [x, y],
            Lens::OpenCv {
                radial: [k1, k2, k3, k4, k5, k6],
                tangential: [p1, p2],
            } => {
                let (x2, y2, xy) = (x * x, y * y, x * y);
                let r2 = x2 + y2;
                let numerator = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                let denominator = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6));
                let radial = numerator / denominator;
                [
                    x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2),
                    y * radial + 2.0 * p2 * xy + p1 * (r2 + 2.0 * y2),
                ]
            }
            Lens::Fisheye {
                k: [k1, k2, k3, k4],
            } => {
                let r = (x * x + y * y).sqrt();
                if r <= f64::EPSILON {
                    return [x, y];
                }
                let theta = r.atan();
                let t2 = theta * theta;
                let theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
                let factor = theta_d / r;
                [x * factor, y * factor]
            }
            Lens::Fov { omega } => {
                let factor = fov_factor(omega, x * x + y * y);
                [x * factor, y * factor]
            }
        }
    }

    /// Undistorts a normalised coordinate of the distorted camera (the inverse of
    /// [`Lens::distort`]) by Newton's method; `None` when it does not converge (a point outside
    /// the region where the model is invertible).
    pub fn undistort(&self, target: [f64; 2]) -> Option<[f64; 2]> {
        if self.is_pinhole() {
            return Some(target);
        }
        let residual = |point: [f64; 2]| {
            let [x, y] = self.distort(point);
            [x - target[0], y - target[1]]
        };
        let mut point = target;
        for _ in 0..100 {
            let [fx, fy] = residual(point);
            if !(fx.is_finite() && fy.is_finite()) {
                return None;
            }
            if fx.abs().max(fy.abs()) < 1e-14 {
                return Some(point);
            }
            // Central differences: the Jacobian of distort at `point`.
            let step = 1e-7 * point[0].abs().max(point[1].abs()).max(1.0);
            let [ax, ay] = self.distort([point[0] + step, point[1]]);
            let [bx, by] = self.distort([point[0] - step, point[1]]);
            let [cx, cy] = self.distort([point[0], point[1] + step]);
            let [dx, dy] = self.distort([point[0], point[1] - step]);
            let (j00, j10) = ((ax - bx) / (2.0 * step), (ay - by) / (2.0 * step));
            let (j01, j11) = ((cx - dx) / (2.0 * step), (cy - dy) / (2.0 * step));
            let determinant = j00 * j11 - j01 * j10;
            if !determinant.is_finite() || determinant.abs() < 1e-12 {
                return None;
            }
            point = [
                point[0] - (j11 * fx - j01 * fy) / determinant,
                point[1] - (-j10 * fx + j00 * fy) / determinant,
            ];
        }
        let [fx, fy] = residual(point);
        (fx.abs().max(fy.abs()) < 1e-10).then_some(point)
    }
}

/// COLMAP's FOV distortion factor `atan(2 r tan(ω/2)) / (r ω)` with its series near ω = 0 and
/// r = 0.
fn fov_factor(omega: f64, radius2: f64) -> f64 {
    const EPSILON: f64 = 1e-4;
    let omega2 = omega * omega;
    if omega2 < EPSILON {
        (omega2 * radius2) / 3.0 - omega2 / 12.0 + 1.0
    } else if radius2 < EPSILON {
        let tan_half = (omega / 2.0).tan();
        (-2.0 * tan_half * (4.0 * radius2 * tan_half * tan_half - 3.0)) / (3.0 * omega)
    } else {
        let radius = radius2.sqrt();
        (radius * 2.0 * (omega / 2.0).tan()).atan() / (radius * omega)
    }
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

/// The distorted pixel (`i + 0.5` centres) seen through the pinhole pixel `pixel` of a camera
/// with `intrinsics` and `lens`.
pub fn distort_pixel(intrinsics: &Intrinsics, lens: &Lens, [u, v]: [f64; 2]) -> [f64; 2] {
    let normalised = [
        (u - intrinsics.cx) / intrinsics.fx,
        (v - intrinsics.cy) / intrinsics.fy,
    ];
    let [x, y] = lens.distort(normalised);
    [
        intrinsics.fx * x + intrinsics.cx,
        intrinsics.fy * y + intrinsics.cy,
    ]
}

/// The pinhole pixel of a distorted one (the inverse of [`distort_pixel`]); `None` where the
/// model cannot be inverted.
pub fn undistort_pixel(intrinsics: &Intrinsics, lens: &Lens, [u, v]: [f64; 2]) -> Option<[f64; 2]> {
    let normalised = [
        (u - intrinsics.cx) / intrinsics.fx,
        (v - intrinsics.cy) / intrinsics.fy,
    ];
    let [x, y] = lens.undistort(normalised)?;
    Some([
        intrinsics.fx * x + intrinsics.cx,
        intrinsics.fy * y + intrinsics.cy,
    ])
}

/// How an undistorted image was made: the share of output pixels whose source lay outside the
/// input (filled from the nearest edge pixel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RemapStats {
    pub outside_fraction: f64,
}

/// Source position (in pixel-index space: pixel `i`'s centre at `i`) of every output pixel of one
/// row, through `lens`.
fn source_row(intrinsics: &Intrinsics, lens: &Lens, row: u32, width: u32) -> Vec<[f32; 2]> {
    let v = f64::from(row) + 0.5;
    (0..width)
        .map(|column| {
            let [su, sv] = distort_pixel(intrinsics, lens, [f64::from(column) + 0.5, v]);
            [(su - 0.5) as f32, (sv - 0.5) as f32]
        })
        .collect()
}

fn is_outside([x, y]: [f32; 2], width: u32, height: u32) -> bool {
    !(x >= -0.5 && y >= -0.5 && x <= width as f32 - 0.5 && y <= height as f32 - 0.5)
}

/// `image` (taken with `intrinsics` and `lens`; its size must be the camera's) remapped to the
/// pinhole camera with the same intrinsics, sampling bilinearly; rows in parallel.
pub fn undistort_rgb(
    image: &Rgb32FImage,
    intrinsics: &Intrinsics,
    lens: &Lens,
) -> (Rgb32FImage, RemapStats) {
    let (width, height) = image.dimensions();
    if width == 0 || height == 0 {
        return (
            image.clone(),
            RemapStats {
                outside_fraction: 0.0,
            },
        );
    }
    let source = image.as_raw();
    let max_x = (width - 1) as f32;
    let max_y = (height - 1) as f32;
    let mut output = Rgb32FImage::new(width, height);
    let outside: usize = output
        .par_chunks_mut(width as usize * 3)
        .enumerate()
        .map(|(row, out_row)| {
            let mut outside = 0;
            for (column, position) in source_row(intrinsics, lens, row as u32, width)
                .into_iter()
                .enumerate()
            {
                outside += usize::from(is_outside(position, width, height));
                let x = position[0].clamp(0.0, max_x);
                let y = position[1].clamp(0.0, max_y);
                let (x0, y0) = (x.floor(), y.floor());
                let (tx, ty) = (x - x0, y - y0);
                let (x0, y0) = (x0 as usize, y0 as usize);
                let x1 = (x0 + 1).min(width as usize - 1);
                let y1 = (y0 + 1).min(height as usize - 1);
                let at = |xx: usize, yy: usize| (yy * width as usize + xx) * 3;
                let (a, b, c, d) = (at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1));
                for channel in 0..3 {
                    let top = source[a + channel] * (1.0 - tx) + source[b + channel] * tx;
                    let bottom = source[c + channel] * (1.0 - tx) + source[d + channel] * tx;
                    out_row[column * 3 + channel] = top * (1.0 - ty) + bottom * ty;
                }
            }
            outside
        })
        .sum();
    let stats = RemapStats {
        outside_fraction: outside as f64 / (f64::from(width) * f64::from(height)).max(1.0),
    };
    (output, stats)
}

/// `mask` (taken with `intrinsics` and `lens`) remapped to the pinhole camera with the same
/// intrinsics, taking the nearest pixel so instance ids are never blended.
pub fn undistort_mask(
    mask: &InstanceMask,
    intrinsics: &Intrinsics,
    lens: &Lens,
) -> (InstanceMask, RemapStats) {
    let (width, height) = (mask.width, mask.height);
    if width == 0 || height == 0 || mask.ids.len() != width as usize * height as usize {
        return (
            mask.clone(),
            RemapStats {
                outside_fraction: 0.0,
            },
        );
    }
    let mut ids = vec![0u32; mask.ids.len()];
    let outside: usize = ids
        .par_chunks_mut(width as usize)
        .enumerate()
        .map(|(row, out_row)| {
            let mut outside = 0;
            for (out, position) in out_row
                .iter_mut()
                .zip(source_row(intrinsics, lens, row as u32, width))
            {
                outside += usize::from(is_outside(position, width, height));
                let x = (position[0] + 0.5).floor().clamp(0.0, (width - 1) as f32) as usize;
                let y = (position[1] + 0.5).floor().clamp(0.0, (height - 1) as f32) as usize;
                *out = mask.ids[y * width as usize + x];
            }
            outside
        })
        .sum();
    let stats = RemapStats {
        outside_fraction: outside as f64 / (f64::from(width) * f64::from(height)).max(1.0),
    };
    (InstanceMask { width, height, ids }, stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn intrinsics(model: &str, distortion: &[f64]) -> Intrinsics {
        Intrinsics {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 52.0,
            cx: 31.0,
            cy: 25.0,
            model: model.to_string(),
            distortion: distortion.to_vec(),
        }
    }

    fn lens(model: &str, distortion: &[f64]) -> Lens {
        Lens::from_intrinsics(&intrinsics(model, distortion)).unwrap()
    }

    fn assert_close(actual: [f64; 2], expected: [f64; 2], tolerance: f64) {
        let error = (actual[0] - expected[0])
            .abs()
            .max((actual[1] - expected[1]).abs());
        assert!(
            error <= tolerance,
            "{actual:?} vs {expected:?}: {error:e} > {tolerance:e}"
        );
    }

    #[test]
    fn known_values() {
        // OPENCV, worked by hand: r² = 0.13, radial = 1 + 0.1 r² + 0.01 r⁴ = 1.013169.
        let opencv = lens("OPENCV", &[0.1, 0.01, 0.001, 0.002]);
        assert_close(
            opencv.distort([0.3, -0.2]),
            [
                0.3 * 1.013169 + 2.0 * 0.001 * 0.3 * -0.2 + 0.002 * (0.13 + 2.0 * 0.09),
                -0.2 * 1.013169 + 2.0 * 0.002 * 0.3 * -0.2 + 0.001 * (0.13 + 2.0 * 0.04),
            ],
            1e-12,
        );
        // SIMPLE_RADIAL at r² = 0.25: factor 1 + 0.25 k.
        assert_close(
            lens("SIMPLE_RADIAL", &[-0.2]).distort([0.3, 0.4]),
            [0.3 * 0.95, 0.4 * 0.95],
            1e-12,
        );
        // RADIAL: 1 + k1 r² + k2 r⁴ at r² = 0.25.
        assert_close(
            lens("RADIAL", &[0.1, -0.04]).distort([0.3, 0.4]),
            [0.3 * 1.0225, 0.4 * 1.0225],
            1e-12,
        );
        // FULL_OPENCV's rational radial term: (1 + 0.1 + 0.01 + 0.001) / (1 + 0.2 + 0.02 + 0.002)
        // at r² = 1 (no tangential terms).
        assert_close(
            lens(
                "FULL_OPENCV",
                &[0.1, 0.01, 0.0, 0.0, 0.001, 0.2, 0.02, 0.002],
            )
            .distort([0.6, 0.8]),
            [0.6 * 1.111 / 1.222, 0.8 * 1.111 / 1.222],
            1e-12,
        );
        // OPENCV_FISHEYE on the x axis: x_d = θ (1 + k1 θ²), θ = atan 0.5.
        let theta = 0.5f64.atan();
        assert_close(
            lens("OPENCV_FISHEYE", &[0.1, 0.0, 0.0, 0.0]).distort([0.5, 0.0]),
            [theta * (1.0 + 0.1 * theta * theta), 0.0],
            1e-12,
        );
        // FOV: r_d = atan(2 r tan(ω/2)) / ω.
        let omega = 0.9f64;
        assert_close(
            lens("FOV", &[omega]).distort([0.5, 0.0]),
            [(2.0 * 0.5 * (omega / 2.0).tan()).atan() / omega, 0.0],
            1e-12,
        );
    }

    #[test]
    fn zero_coefficients_are_the_identity() {
        for (model, count) in [
            ("PINHOLE", 0),
            ("SIMPLE_RADIAL", 1),
            ("RADIAL", 2),
            ("OPENCV", 4),
            ("FULL_OPENCV", 8),
            ("FOV", 1),
        ] {
            let lens = lens(model, &vec![0.0; count]);
            assert!(lens.is_pinhole(), "{model}");
            for point in [[0.0, 0.0], [0.3, -0.7], [-1.2, 0.9]] {
                assert_eq!(lens.distort(point), point, "{model}");
            }
        }
        // A fisheye with zero coefficients is the equidistant projection, not a pinhole.
        let fisheye = lens("OPENCV_FISHEYE", &[0.0; 4]);
        assert!(!fisheye.is_pinhole());
        assert_close(
            fisheye.distort([1.0, 0.0]),
            [std::f64::consts::FRAC_PI_4, 0.0],
            1e-12,
        );
        let image = Rgb32FImage::from_fn(8, 6, |x, y| image::Rgb([x as f32, y as f32, 0.5]));
        let camera = intrinsics("OPENCV", &[0.0; 4]);
        let (same, stats) =
            undistort_rgb(&image, &camera, &Lens::from_intrinsics(&camera).unwrap());
        assert_eq!(same, image);
        assert_eq!(stats.outside_fraction, 0.0);
    }

    #[test]
    fn distorted_points_undistort_back() {
        let lenses = [
            lens("SIMPLE_RADIAL", &[-0.12]),
            lens("RADIAL", &[0.08, -0.01]),
            lens("OPENCV", &[-0.28, 0.09, 0.0012, -0.0009]),
            lens("OPENCV", &[0.12, 0.03, -0.002, 0.001]),
            lens(
                "FULL_OPENCV",
                &[0.2, -0.05, 0.001, 0.002, 0.01, 0.1, -0.02, 0.003],
            ),
            lens("OPENCV_FISHEYE", &[0.05, -0.01, 0.002, -0.0003]),
            lens("SIMPLE_RADIAL_FISHEYE", &[0.03]),
            lens("RADIAL_FISHEYE", &[0.03, -0.004]),
            lens("FOV", &[0.8]),
        ];
        for lens in &lenses {
            for i in -6..=6 {
                for j in -4..=4 {
                    let point = [f64::from(i) * 0.1, f64::from(j) * 0.1];
                    let distorted = lens.distort(point);
                    let back = lens.undistort(distorted).expect("converges");
                    assert_close(back, point, 1e-9);
                }
            }
        }
        let camera = intrinsics("OPENCV", &[-0.28, 0.09, 0.0012, -0.0009]);
        let opencv = Lens::from_intrinsics(&camera).unwrap();
        let pixel = [5.5, 40.25];
        let distorted = distort_pixel(&camera, &opencv, pixel);
        assert!((distorted[0] - pixel[0]).abs() > 1.0);
        assert_close(
            undistort_pixel(&camera, &opencv, distorted).unwrap(),
            pixel,
            1e-6,
        );
    }

    #[test]
    fn bad_cameras_are_refused_with_the_reason() {
        let error = |model: &str, distortion: &[f64]| {
            Lens::from_intrinsics(&intrinsics(model, distortion)).unwrap_err()
        };
        assert!(error("THIN_PRISM_FISHEYE", &[0.0; 8]).contains("THIN_PRISM_FISHEYE cannot be"));
        assert!(error("KANNALA", &[]).contains("unknown camera model \"KANNALA\""));
        let nan = error("OPENCV", &[0.1, f64::NAN, 0.0, 0.0]);
        assert!(nan.contains("parameter 2 (k2) is NaN"), "{nan}");
        assert!(error("OPENCV", &[0.1]).contains("expected 4 distortion parameters, found 1"));
        let mut infinite = intrinsics("PINHOLE", &[]);
        infinite.fx = f64::INFINITY;
        assert!(
            Lens::from_intrinsics(&infinite)
                .unwrap_err()
                .contains("fx is inf")
        );
        infinite.fx = -3.0;
        assert!(
            Lens::from_intrinsics(&infinite)
                .unwrap_err()
                .contains("positive")
        );
    }

    #[test]
    fn masks_keep_their_labels() {
        // Vertical stripes of ids 0, 7, 300 under strong barrel distortion.
        let camera = intrinsics("OPENCV", &[-0.3, 0.1, 0.002, -0.001]);
        let lens = Lens::from_intrinsics(&camera).unwrap();
        let (width, height) = (camera.width, camera.height);
        let ids: Vec<u32> = (0..height)
            .flat_map(|_| (0..width).map(|x| [0, 7, 300][(x / 22) as usize]))
            .collect();
        let mask = InstanceMask { width, height, ids };
        let (undistorted, stats) = undistort_mask(&mask, &camera, &lens);
        assert_eq!(
            stats.outside_fraction, 0.0,
            "barrel: every source is inside"
        );
        assert!(undistorted.ids.iter().all(|id| [0, 7, 300].contains(id)));
        assert_ne!(undistorted.ids, mask.ids);
        // Each output pixel has the id of the input pixel nearest its distorted position.
        for (index, id) in undistorted.ids.iter().enumerate() {
            let (x, y) = (index as u32 % width, index as u32 / width);
            let [u, v] = distort_pixel(&camera, &lens, [f64::from(x) + 0.5, f64::from(y) + 0.5]);
            let source_x = (u.floor() as u32).min(width - 1);
            let source_y = (v.floor() as u32).min(height - 1);
            assert_eq!(*id, mask.ids[(source_y * width + source_x) as usize]);
        }
    }
}

#[cfg(test)]
mod cost {
    use super::*;

    /// The cost of undistorting one phone frame (1080x1920, OPENCV) at load; run with
    /// `cargo test --lib scene::distortion::cost -- --ignored --nocapture`.
    #[test]
    #[ignore = "timing, prints the cost"]
    fn undistort_a_1080x1920_frame() {
        let camera = Intrinsics {
            width: 1080,
            height: 1920,
            fx: 1450.0,
            fy: 1450.0,
            cx: 540.0,
            cy: 960.0,
            model: "OPENCV".to_string(),
            distortion: vec![0.08, -0.15, 0.001, -0.0005],
        };
        let lens = Lens::from_intrinsics(&camera).unwrap();
        let image = Rgb32FImage::from_fn(1080, 1920, |x, y| {
            image::Rgb([(x % 7) as f32 / 7.0, (y % 5) as f32 / 5.0, 0.5])
        });
        let mask = InstanceMask {
            width: 1080,
            height: 1920,
            ids: (0..1080 * 1920).map(|i| (i % 13) as u32).collect(),
        };
        for _ in 0..2 {
            let start = std::time::Instant::now();
            let (_, stats) = undistort_rgb(&image, &camera, &lens);
            let rgb = start.elapsed();
            let start = std::time::Instant::now();
            undistort_mask(&mask, &camera, &lens);
            let ids = start.elapsed();
            println!(
                "1080x1920 OPENCV on {} threads: image {rgb:?}, mask {ids:?}, {:.2}% from outside",
                rayon::current_num_threads(),
                stats.outside_fraction * 100.0
            );
        }
    }
}
