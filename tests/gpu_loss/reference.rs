//! The f64 CPU reference of the render loss (direct 2D window, not separable), the test images,
//! and the reference's own gradient checked by central finite differences.

use rand::Rng;
use segsplat_engine::loss::{DSSIM_WEIGHT, L1_WEIGHT, SSIM_C1, SSIM_C2, ssim_window};

use crate::gpu_support::seeded_rng;

pub(crate) type Rgb = [f64; 3];

/// Zero-padded 2D filtering with the 11x11 window (outer product of the 1D taps).
fn filter_2d(values: &[f64], width: usize, height: usize) -> Vec<f64> {
    let taps = ssim_window();
    let radius = (taps.len() / 2) as isize;
    let mut out = vec![0.0; values.len()];
    for y in 0..height as isize {
        for x in 0..width as isize {
            let mut sum = 0.0;
            for (dy, ty) in taps.iter().enumerate() {
                for (dx, tx) in taps.iter().enumerate() {
                    let (sx, sy) = (x + dx as isize - radius, y + dy as isize - radius);
                    if sx >= 0 && sy >= 0 && sx < width as isize && sy < height as isize {
                        sum += ty * tx * values[sy as usize * width + sx as usize];
                    }
                }
            }
            out[y as usize * width + x as usize] = sum;
        }
    }
    out
}

/// Loss and dL/d(rendered), f64, unweighted.
pub(crate) fn cpu_loss(
    rendered: &[Rgb],
    target: &[Rgb],
    width: usize,
    height: usize,
) -> (f64, Vec<Rgb>) {
    let c1 = f64::from(SSIM_C1);
    let c2 = f64::from(SSIM_C2);
    let n = (width * height * 3) as f64;
    let mut l1_sum = 0.0;
    let mut ssim_sum = 0.0;
    let mut grad = vec![[0.0; 3]; rendered.len()];
    for channel in 0..3 {
        let r: Vec<f64> = rendered.iter().map(|p| p[channel]).collect();
        let t: Vec<f64> = target.iter().map(|p| p[channel]).collect();
        let product =
            |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(x, y)| x * y).collect() };
        let mu_r = filter_2d(&r, width, height);
        let mu_t = filter_2d(&t, width, height);
        let m_rr = filter_2d(&product(&r, &r), width, height);
        let m_tt = filter_2d(&product(&t, &t), width, height);
        let m_rt = filter_2d(&product(&r, &t), width, height);
        let mut d_mu = vec![0.0; r.len()];
        let mut d_rr = vec![0.0; r.len()];
        let mut d_rt = vec![0.0; r.len()];
        for p in 0..r.len() {
            let var_r = m_rr[p] - mu_r[p] * mu_r[p];
            let var_t = m_tt[p] - mu_t[p] * mu_t[p];
            let cov = m_rt[p] - mu_r[p] * mu_t[p];
            let a = 2.0 * mu_r[p] * mu_t[p] + c1;
            let b = 2.0 * cov + c2;
            let c = mu_r[p] * mu_r[p] + mu_t[p] * mu_t[p] + c1;
            let d = var_r + var_t + c2;
            let ssim = a * b / (c * d);
            ssim_sum += ssim;
            // d ssim / d(mu_r) with the second moments held fixed.
            d_mu[p] = (2.0 * mu_t[p] * b - 2.0 * mu_t[p] * a) / (c * d) - 2.0 * mu_r[p] * ssim / c
                + 2.0 * mu_r[p] * ssim / d;
            d_rr[p] = -ssim / d;
            d_rt[p] = 2.0 * a / (c * d);
            l1_sum += (r[p] - t[p]).abs();
        }
        let g_mu = filter_2d(&d_mu, width, height);
        let g_rr = filter_2d(&d_rr, width, height);
        let g_rt = filter_2d(&d_rt, width, height);
        for q in 0..r.len() {
            let dssim_dr = g_mu[q] + 2.0 * r[q] * g_rr[q] + t[q] * g_rt[q];
            let sign = (r[q] - t[q]).signum() * f64::from(u8::from(r[q] != t[q]));
            grad[q][channel] =
                (f64::from(L1_WEIGHT) * sign - f64::from(DSSIM_WEIGHT) * dssim_dr) / n;
        }
    }
    let loss = f64::from(L1_WEIGHT) * l1_sum / n + f64::from(DSSIM_WEIGHT) * (1.0 - ssim_sum / n);
    (loss, grad)
}

/// The reference loss's derivative in one pixel's channel by a central difference of `step`.
pub(crate) fn central_difference(
    rendered: &[Rgb],
    target: &[Rgb],
    (width, height): (usize, usize),
    (pixel, channel): (usize, usize),
    step: f64,
) -> f64 {
    let mut plus = rendered.to_vec();
    let mut minus = rendered.to_vec();
    plus[pixel][channel] += step;
    minus[pixel][channel] -= step;
    (cpu_loss(&plus, target, width, height).0 - cpu_loss(&minus, target, width, height).0)
        / (2.0 * step)
}

/// A smooth random target and a rendering near it (so SSIM is far from 0 and L1 has no kinks).
pub(crate) fn test_images(rng: &mut impl Rng, width: usize, height: usize) -> (Vec<Rgb>, Vec<Rgb>) {
    let phase: [f64; 3] = [rng.random(), rng.random(), rng.random()];
    let target: Vec<Rgb> = (0..width * height)
        .map(|p| {
            let (x, y) = ((p % width) as f64, (p / width) as f64);
            std::array::from_fn(|c| {
                0.5 + 0.3 * (0.4 * x + 0.3 * y + 6.0 * phase[c]).sin() + 0.1 * rng.random::<f64>()
            })
        })
        .collect();
    let rendered = target
        .iter()
        .map(|t| t.map(|v| (v + rng.random_range(-0.15..0.15)).clamp(0.0, 1.0)))
        .collect();
    (rendered, target)
}

pub(crate) fn to_vec4(image: &[Rgb], alpha: f32) -> Vec<[f32; 4]> {
    image
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32, alpha])
        .collect()
}

#[test]
fn cpu_reference_gradient_matches_finite_differences() {
    let mut rng = seeded_rng(1);
    let (width, height) = (13, 9);
    let (rendered, target) = test_images(&mut rng, width, height);
    let (_, grad) = cpu_loss(&rendered, &target, width, height);
    let step = 1e-6;
    for pixel in [0, 5, width + 3, width * 4 + 6, width * height - 1] {
        for (channel, &analytic) in grad[pixel].iter().enumerate() {
            let numeric =
                central_difference(&rendered, &target, (width, height), (pixel, channel), step);
            assert!(
                (numeric - analytic).abs() <= 1e-6 * analytic.abs().max(1e-4),
                "pixel {pixel} channel {channel}: numeric {numeric:e} analytic {analytic:e}"
            );
        }
    }
}
