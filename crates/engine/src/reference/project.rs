//! Projection of one 3D Gaussian to a screen-space splat (EWA), and its vector-Jacobian product.

// Index loops mirror the matrix formulas they implement.
#![allow(clippy::needless_range_loop)]

use glam::{DMat2, DMat3, DVec2, DVec3};

use super::sh;
use super::{ReferenceCamera, ReferenceGaussians};
use crate::{ALPHA_MIN, COVARIANCE_DILATION, RADIUS_SIGMAS, RenderSettings};

/// A Gaussian as the rasteriser sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedGaussian {
    /// Pixel coordinates of the centre (pixel (u, v) has its centre at (u + 0.5, v + 0.5)).
    pub mean2d: DVec2,
    /// Inverse 2D covariance (a, b, c) = [[a, b], [b, c]].
    pub conic: [f64; 3],
    pub opacity: f64,
    /// SH colour + 0.5, clamped at 0.
    pub colour: [f64; 3],
    /// Channels whose unclamped colour was negative (zero gradient).
    pub colour_clamped: [bool; 3],
    /// Camera-space z.
    pub depth: f64,
    /// 3DGS's screen radius: three standard deviations along the major axis, rounded up.
    pub radius: f64,
}

/// Gradients of a loss with respect to one projected Gaussian.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ProjectedGrad {
    pub mean2d: DVec2,
    pub conic: [f64; 3],
    pub opacity: f64,
    pub colour: [f64; 3],
    /// Sum of |d loss / d mean2d| per pixel.
    pub mean2d_abs: DVec2,
}

fn normalised_quaternion(q: [f64; 4]) -> ([f64; 4], f64) {
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    (q.map(|v| v / norm), norm)
}

/// Rotation matrix of a unit quaternion (w, x, y, z).
fn rotation_matrix(q: [f64; 4]) -> DMat3 {
    let [w, x, y, z] = q;
    let rows = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    DMat3::from_cols_array_2d(&rows).transpose()
}

/// Row `r`, column `c`.
fn entry(m: DMat3, r: usize, c: usize) -> f64 {
    m.col(c)[r]
}

/// Everything the projection computes that its backward needs again.
struct Geometry {
    rotation: DMat3,
    unit_quaternion: [f64; 4],
    quaternion_norm: f64,
    scales: DVec3,
    scale_rotation: DMat3,
    mean_camera: DVec3,
    covariance_camera: DMat3,
    jacobian_x_clamped: bool,
    jacobian_y_clamped: bool,
    limit: [f64; 2],
    jacobian: [[f64; 3]; 2],
    /// Dilated 2D covariance.
    covariance_2d: DMat2,
    conic: DMat2,
}

fn geometry(gaussians: &ReferenceGaussians, index: usize, camera: &ReferenceCamera) -> Geometry {
    let (unit_quaternion, quaternion_norm) = normalised_quaternion(gaussians.rotations[index]);
    let rotation = rotation_matrix(unit_quaternion);
    let scales = DVec3::from_array(gaussians.log_scales[index]).exp();
    let scale_rotation = rotation * DMat3::from_diagonal(scales);
    let covariance = scale_rotation * scale_rotation.transpose();
    let w = camera.rotation;
    let mean_camera = w * DVec3::from_array(gaussians.means[index]) + camera.translation;
    let covariance_camera = w * covariance * w.transpose();

    let z = mean_camera.z;
    let limit = camera.jacobian_limit;
    let ratio = [mean_camera.x / z, mean_camera.y / z];
    let clamped = [
        ratio[0].clamp(-limit[0], limit[0]),
        ratio[1].clamp(-limit[1], limit[1]),
    ];
    let tx = clamped[0] * z;
    let ty = clamped[1] * z;
    let jacobian = [
        [camera.fx / z, 0.0, -camera.fx * tx / (z * z)],
        [0.0, camera.fy / z, -camera.fy * ty / (z * z)],
    ];
    let j = jacobian;
    let sc = covariance_camera;
    // cov2d = J Sc J^T
    let mut cov2d = [[0.0; 2]; 2];
    for (r, row) in cov2d.iter_mut().enumerate() {
        for (c, value) in row.iter_mut().enumerate() {
            let mut sum = 0.0;
            for a in 0..3 {
                for b in 0..3 {
                    sum += j[r][a] * entry(sc, a, b) * j[c][b];
                }
            }
            *value = sum;
        }
    }
    let dilation = COVARIANCE_DILATION as f64;
    let cov = DMat2::from_cols_array_2d(&[
        [cov2d[0][0] + dilation, cov2d[1][0]],
        [cov2d[0][1], cov2d[1][1] + dilation],
    ]);
    Geometry {
        rotation,
        unit_quaternion,
        quaternion_norm,
        scales,
        scale_rotation,
        mean_camera,
        covariance_camera,
        jacobian_x_clamped: ratio[0] != clamped[0],
        jacobian_y_clamped: ratio[1] != clamped[1],
        limit,
        jacobian,
        covariance_2d: cov,
        conic: cov.inverse(),
    }
}

/// Projects Gaussian `index`, or `None` when it is culled (filtered out, at or before the near
/// plane, at or beyond the far plane, degenerate, too transparent to reach alpha 1/255 anywhere,
/// or with that footprint off screen).
pub fn project_gaussian(
    gaussians: &ReferenceGaussians,
    index: usize,
    camera: &ReferenceCamera,
    settings: &RenderSettings,
) -> Option<ProjectedGaussian> {
    if !settings.filter.keeps(gaussians.object_ids[index]) {
        return None;
    }
    let mean_camera =
        camera.rotation * DVec3::from_array(gaussians.means[index]) + camera.translation;
    let z = mean_camera.z;
    if z <= camera.near || z >= camera.far {
        return None;
    }
    let g = geometry(gaussians, index, camera);
    let cov = g.covariance_2d;
    let (a, b, c) = (cov.col(0).x, cov.col(0).y, cov.col(1).y);
    let det = a * c - b * b;
    if det <= 0.0 {
        return None;
    }
    let conic = [c / det, -b / det, a / det];
    let mid = 0.5 * (a + c);
    let lambda = mid + (mid * mid - det).max(0.1).sqrt();
    let radius = (RADIUS_SIGMAS as f64 * lambda.sqrt()).ceil();
    let mean2d = DVec2::new(
        camera.fx * mean_camera.x / z + camera.cx,
        camera.fy * mean_camera.y / z + camera.cy,
    );
    let opacity = 1.0 / (1.0 + (-gaussians.opacity_logits[index]).exp());
    // Where alpha = opacity * exp(-sigma) can reach ALPHA_MIN: sigma <= ln(opacity / ALPHA_MIN),
    // an ellipse reaching sqrt(2 sigma cov_kk) along axis k.
    let sigma_max = (opacity / ALPHA_MIN as f64).ln();
    if sigma_max <= 0.0 {
        return None;
    }
    let reach = DVec2::new((2.0 * sigma_max * a).sqrt(), (2.0 * sigma_max * c).sqrt());
    let image = DVec2::new(camera.width as f64, camera.height as f64);
    let footprint_min = mean2d - reach;
    let footprint_max = mean2d + reach;
    if footprint_max.x <= 0.0
        || footprint_max.y <= 0.0
        || footprint_min.x >= image.x
        || footprint_min.y >= image.y
    {
        return None;
    }
    let (colour, colour_clamped) = colour(gaussians, index, camera, settings.sh_degree);
    Some(ProjectedGaussian {
        mean2d,
        conic,
        opacity,
        colour,
        colour_clamped,
        depth: z,
        radius,
    })
}

fn view_direction(
    gaussians: &ReferenceGaussians,
    index: usize,
    camera: &ReferenceCamera,
) -> (DVec3, f64) {
    let offset = DVec3::from_array(gaussians.means[index]) - camera.position;
    let length = offset.length();
    (offset / length, length)
}

fn colour(
    gaussians: &ReferenceGaussians,
    index: usize,
    camera: &ReferenceCamera,
    sh_degree: u32,
) -> ([f64; 3], [bool; 3]) {
    let (direction, _) = view_direction(gaussians, index, camera);
    let basis = sh::basis(sh_degree, direction.to_array());
    let coefficients = &gaussians.sh_coefficients[index];
    let mut colour = [0.5; 3];
    for (k, b) in basis.iter().enumerate() {
        for (channel, value) in colour.iter_mut().enumerate() {
            *value += b * coefficients[k][channel];
        }
    }
    let clamped = colour.map(|v| v < 0.0);
    (colour.map(|v| v.max(0.0)), clamped)
}

/// Adds the gradients of Gaussian `index`'s parameters, given the gradients of its projection,
/// into `grads` (same indexing as `gaussians`).
pub fn project_backward(
    gaussians: &ReferenceGaussians,
    index: usize,
    camera: &ReferenceCamera,
    settings: &RenderSettings,
    projected: &ProjectedGaussian,
    v: &ProjectedGrad,
    grads: &mut ReferenceGaussians,
) {
    let g = geometry(gaussians, index, camera);
    let (fx, fy) = (camera.fx, camera.fy);
    let p = g.mean_camera;
    let z = p.z;

    // Opacity.
    let o = projected.opacity;
    grads.opacity_logits[index] += v.opacity * o * (1.0 - o);

    // Colour -> SH coefficients and view direction.
    let v_colour: [f64; 3] = std::array::from_fn(|c| {
        if projected.colour_clamped[c] {
            0.0
        } else {
            v.colour[c]
        }
    });
    let (direction, distance) = view_direction(gaussians, index, camera);
    let basis = sh::basis(settings.sh_degree, direction.to_array());
    let basis_gradient = sh::basis_gradient(settings.sh_degree, direction.to_array());
    let mut v_direction = DVec3::ZERO;
    for k in 0..16 {
        for c in 0..3 {
            grads.sh_coefficients[index][k][c] += basis[k] * v_colour[c];
            let weight = gaussians.sh_coefficients[index][k][c] * v_colour[c];
            v_direction += DVec3::from_array(basis_gradient[k]) * weight;
        }
    }
    let mut v_mean_world = (v_direction - direction * direction.dot(v_direction)) / distance;

    // Conic -> 2D covariance: d conic = -conic d cov conic.
    let v_conic = DMat2::from_cols_array_2d(&[
        [v.conic[0], 0.5 * v.conic[1]],
        [0.5 * v.conic[1], v.conic[2]],
    ]);
    let v_cov2d = -(g.conic * v_conic * g.conic);
    let v_cov = [
        [v_cov2d.col(0).x, v_cov2d.col(1).x],
        [v_cov2d.col(0).y, v_cov2d.col(1).y],
    ];
    let j = g.jacobian;
    let sc = g.covariance_camera;
    // cov2d = J Sc J^T: v_Sc = J^T V J, v_J = 2 V J Sc (V, Sc symmetric).
    let mut v_sc = [[0.0; 3]; 3];
    for (a, row) in v_sc.iter_mut().enumerate() {
        for (b, value) in row.iter_mut().enumerate() {
            let mut sum = 0.0;
            for r in 0..2 {
                for c in 0..2 {
                    sum += j[r][a] * v_cov[r][c] * j[c][b];
                }
            }
            *value = sum;
        }
    }
    let mut v_j = [[0.0; 3]; 2];
    for (r, row) in v_j.iter_mut().enumerate() {
        for (b, value) in row.iter_mut().enumerate() {
            let mut sum = 0.0;
            for c in 0..2 {
                for a in 0..3 {
                    sum += v_cov[r][c] * j[c][a] * entry(sc, a, b);
                }
            }
            *value = 2.0 * sum;
        }
    }

    // Mean in camera space: from mean2d and from the Jacobian.
    let mut v_p = DVec3::new(
        v.mean2d.x * fx / z,
        v.mean2d.y * fy / z,
        -(v.mean2d.x * fx * p.x + v.mean2d.y * fy * p.y) / (z * z),
    );
    v_p.z += -fx / (z * z) * v_j[0][0] - fy / (z * z) * v_j[1][1];
    if g.jacobian_x_clamped {
        let tx_over_z = (p.x / z).clamp(-g.limit[0], g.limit[0]);
        v_p.z += fx * tx_over_z / (z * z) * v_j[0][2];
    } else {
        v_p.x += -fx / (z * z) * v_j[0][2];
        v_p.z += 2.0 * fx * p.x / (z * z * z) * v_j[0][2];
    }
    if g.jacobian_y_clamped {
        let ty_over_z = (p.y / z).clamp(-g.limit[1], g.limit[1]);
        v_p.z += fy * ty_over_z / (z * z) * v_j[1][2];
    } else {
        v_p.y += -fy / (z * z) * v_j[1][2];
        v_p.z += 2.0 * fy * p.y / (z * z * z) * v_j[1][2];
    }
    let w = camera.rotation;
    v_mean_world += w.transpose() * v_p;
    for axis in 0..3 {
        grads.means[index][axis] += v_mean_world[axis];
    }

    // Camera covariance -> world covariance -> M = R S.
    let v_sc_mat = DMat3::from_cols_array_2d(&v_sc).transpose();
    let v_sigma = w.transpose() * v_sc_mat * w;
    let v_m = 2.0 * v_sigma * g.scale_rotation;
    let scales = g.scales;
    let v_r = v_m * DMat3::from_diagonal(scales);
    for axis in 0..3 {
        let v_scale = g.rotation.col(axis).dot(v_m.col(axis));
        grads.log_scales[index][axis] += v_scale * scales[axis];
    }
    let [qw, qx, qy, qz] = g.unit_quaternion;
    let e = |r, c| entry(v_r, r, c);
    let v_unit = [
        2.0 * (-qz * e(0, 1) + qy * e(0, 2) + qz * e(1, 0) - qx * e(1, 2) - qy * e(2, 0)
            + qx * e(2, 1)),
        2.0 * (qy * e(0, 1) + qz * e(0, 2) + qy * e(1, 0) - 2.0 * qx * e(1, 1) - qw * e(1, 2)
            + qz * e(2, 0)
            + qw * e(2, 1)
            - 2.0 * qx * e(2, 2)),
        2.0 * (-2.0 * qy * e(0, 0) + qx * e(0, 1) + qw * e(0, 2) + qx * e(1, 0) + qz * e(1, 2)
            - qw * e(2, 0)
            + qz * e(2, 1)
            - 2.0 * qy * e(2, 2)),
        2.0 * (-2.0 * qz * e(0, 0) - qw * e(0, 1) + qx * e(0, 2) + qw * e(1, 0)
            - 2.0 * qz * e(1, 1)
            + qy * e(1, 2)
            + qx * e(2, 0)
            + qy * e(2, 1)),
    ];
    let dot: f64 = (0..4).map(|k| v_unit[k] * g.unit_quaternion[k]).sum();
    for k in 0..4 {
        grads.rotations[index][k] += (v_unit[k] - g.unit_quaternion[k] * dot) / g.quaternion_norm;
    }
}
