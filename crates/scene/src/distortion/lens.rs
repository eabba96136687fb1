//! The lens models: a camera's distortion in normalised image coordinates, both ways.

use super::parameter_name;
use crate::Intrinsics;

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
