//! Per-pixel front-to-back compositing and its backward pass (reference, f64).

// Index loops mirror the matrix formulas they implement.
#![allow(clippy::needless_range_loop)]

use glam::DVec2;

use super::project::{ProjectedGrad, project_backward};
use super::{
    ProjectedGaussian, ReferenceCamera, ReferenceGaussians, ReferenceGrads, project_gaussian,
};
use crate::{ALPHA_MAX, ALPHA_MIN, RenderCamera, RenderSettings, TRANSMITTANCE_MIN};

/// A reference render and what its backward pass needs.
#[derive(Debug, Clone)]
pub struct ReferenceForward {
    pub camera: ReferenceCamera,
    pub settings: RenderSettings,
    /// Row-major, per pixel (r, g, b, alpha) with the background composited into rgb.
    pub image: Vec<[f64; 4]>,
    /// Per pixel, sum over fragments of weight * camera depth (divide by alpha for mean depth).
    pub depth: Vec<f64>,
    pub final_transmittance: Vec<f64>,
    /// Per Gaussian, its projection (`None` when culled).
    pub projected: Vec<Option<ProjectedGaussian>>,
    /// Per pixel, the Gaussians that contributed, front to back. Identical lists between two
    /// renders mean no fragment crossed a threshold (used by finite-difference tests).
    pub contributors: Vec<Vec<u32>>,
}

/// Gaussian indices of visible splats sorted by depth (stable: ties keep index order, as the GPU's
/// stable radix sort does).
fn depth_order(projected: &[Option<ProjectedGaussian>]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..projected.len() as u32)
        .filter(|&i| projected[i as usize].is_some())
        .collect();
    order.sort_by(|&a, &b| {
        let da = projected[a as usize].map_or(0.0, |p| p.depth as f32);
        let db = projected[b as usize].map_or(0.0, |p| p.depth as f32);
        da.total_cmp(&db)
    });
    order
}

/// Fragment of splat `p` at the pixel whose centre is `pixel`: (alpha, sigma, offset, gaussian
/// value), or `None` when skipped.
fn fragment(p: &ProjectedGaussian, pixel: DVec2) -> Option<(f64, f64, DVec2, f64)> {
    let d = p.mean2d - pixel;
    let [a, b, c] = p.conic;
    let sigma = 0.5 * (a * d.x * d.x + c * d.y * d.y) + b * d.x * d.y;
    if sigma < 0.0 {
        return None;
    }
    let gaussian = (-sigma).exp();
    let alpha = (p.opacity * gaussian).min(ALPHA_MAX as f64);
    if alpha < ALPHA_MIN as f64 {
        return None;
    }
    Some((alpha, sigma, d, gaussian))
}

/// Renders `gaussians` through `camera`.
pub fn render_forward(
    gaussians: &ReferenceGaussians,
    camera: &RenderCamera,
    settings: &RenderSettings,
) -> ReferenceForward {
    let camera = ReferenceCamera::new(camera);
    let projected: Vec<_> = (0..gaussians.len())
        .map(|i| project_gaussian(gaussians, i, &camera, settings))
        .collect();
    let order = depth_order(&projected);
    let pixels = camera.width as usize * camera.height as usize;
    let mut image = vec![[0.0; 4]; pixels];
    let mut depth = vec![0.0; pixels];
    let mut final_transmittance = vec![1.0; pixels];
    let mut contributors = vec![Vec::new(); pixels];
    let background = settings.background.map(f64::from);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let pixel_index = (y * camera.width + x) as usize;
            let centre = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let mut transmittance = 1.0;
            let mut rgb = [0.0; 3];
            for &gaussian in &order {
                let Some(p) = projected[gaussian as usize].as_ref() else {
                    continue;
                };
                let Some((alpha, ..)) = fragment(p, centre) else {
                    continue;
                };
                let next = transmittance * (1.0 - alpha);
                if next <= TRANSMITTANCE_MIN as f64 {
                    break;
                }
                let weight = alpha * transmittance;
                for c in 0..3 {
                    rgb[c] += p.colour[c] * weight;
                }
                depth[pixel_index] += p.depth * weight;
                contributors[pixel_index].push(gaussian);
                transmittance = next;
            }
            image[pixel_index] = [
                rgb[0] + transmittance * background[0],
                rgb[1] + transmittance * background[1],
                rgb[2] + transmittance * background[2],
                1.0 - transmittance,
            ];
            final_transmittance[pixel_index] = transmittance;
        }
    }
    ReferenceForward {
        camera,
        settings: *settings,
        image,
        depth,
        final_transmittance,
        projected,
        contributors,
    }
}

/// Gradients of a loss with respect to every Gaussian parameter, given `grad_image` = d loss /
/// d image (per pixel r, g, b, alpha; the depth output carries no gradient).
pub fn render_backward(
    gaussians: &ReferenceGaussians,
    forward: &ReferenceForward,
    grad_image: &[[f64; 4]],
) -> ReferenceGrads {
    let camera = &forward.camera;
    let background = forward.settings.background.map(f64::from);
    let mut projected_grads = vec![ProjectedGrad::default(); gaussians.len()];
    for y in 0..camera.height {
        for x in 0..camera.width {
            let pixel_index = (y * camera.width + x) as usize;
            let centre = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let v_out = grad_image[pixel_index];
            let final_t = forward.final_transmittance[pixel_index];
            let mut transmittance = final_t;
            let mut behind = [0.0; 3];
            for &gaussian in forward.contributors[pixel_index].iter().rev() {
                let Some(p) = forward.projected[gaussian as usize].as_ref() else {
                    continue;
                };
                let Some((alpha, _sigma, d, value)) = fragment(p, centre) else {
                    continue;
                };
                let one_over_rest = 1.0 / (1.0 - alpha);
                transmittance *= one_over_rest;
                let weight = alpha * transmittance;
                let v = &mut projected_grads[gaussian as usize];
                let mut v_alpha = 0.0;
                for c in 0..3 {
                    v.colour[c] += weight * v_out[c];
                    v_alpha += (p.colour[c] * transmittance - behind[c] * one_over_rest) * v_out[c];
                    v_alpha -= final_t * one_over_rest * background[c] * v_out[c];
                }
                v_alpha += final_t * one_over_rest * v_out[3];
                if p.opacity * value <= ALPHA_MAX as f64 {
                    let v_sigma = -p.opacity * value * v_alpha;
                    let [a, b, c] = p.conic;
                    v.conic[0] += 0.5 * v_sigma * d.x * d.x;
                    v.conic[1] += v_sigma * d.x * d.y;
                    v.conic[2] += 0.5 * v_sigma * d.y * d.y;
                    let v_mean =
                        DVec2::new(v_sigma * (a * d.x + b * d.y), v_sigma * (b * d.x + c * d.y));
                    v.mean2d += v_mean;
                    v.mean2d_abs += v_mean.abs();
                    v.opacity += value * v_alpha;
                }
                for c in 0..3 {
                    behind[c] += p.colour[c] * weight;
                }
            }
        }
    }
    let mut grads = ReferenceGrads {
        parameters: ReferenceGaussians::zeros(gaussians.len()),
        mean2d_abs: vec![[0.0; 2]; gaussians.len()],
    };
    for (index, projected) in forward.projected.iter().enumerate() {
        let Some(p) = projected else { continue };
        let v = &projected_grads[index];
        project_backward(
            gaussians,
            index,
            camera,
            &forward.settings,
            p,
            v,
            &mut grads.parameters,
        );
        grads.mean2d_abs[index] = v.mean2d_abs.to_array();
    }
    grads
}
