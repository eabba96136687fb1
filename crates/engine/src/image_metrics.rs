//! Image quality metrics for held-out views, computed as the 3DGS evaluation does: PSNR over all
//! RGB values, SSIM with an 11x11 Gaussian window (sigma 1.5), zero padding, mean over pixels and
//! channels. f64 throughout, on the CPU: evaluation is rare and must be exact.

/// Peak signal-to-noise ratio in dB for values in [0, 1]; infinite for identical images.
pub fn psnr(rendered: &[[f32; 3]], target: &[[f32; 3]]) -> f64 {
    let count = (rendered.len().min(target.len()) * 3).max(1);
    let squared_error: f64 = rendered
        .iter()
        .zip(target)
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] as f64 - b[c] as f64).powi(2)))
        .sum();
    let mse = squared_error / count as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

const WINDOW: usize = 11;
const SIGMA: f64 = 1.5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

fn window() -> [f64; WINDOW] {
    let mut weights = [0.0; WINDOW];
    let half = (WINDOW / 2) as f64;
    for (i, weight) in weights.iter_mut().enumerate() {
        let x = i as f64 - half;
        *weight = (-x * x / (2.0 * SIGMA * SIGMA)).exp();
    }
    let sum: f64 = weights.iter().sum();
    weights.map(|w| w / sum)
}

/// Separable Gaussian blur with zero padding (as a conv2d with padding 5).
fn blur(values: &[f64], width: usize, height: usize, weights: &[f64; WINDOW]) -> Vec<f64> {
    let half = (WINDOW / 2) as isize;
    let mut horizontal = vec![0.0; values.len()];
    for y in 0..height {
        for x in 0..width {
            let mut sum = 0.0;
            for (k, weight) in weights.iter().enumerate() {
                let sx = x as isize + k as isize - half;
                if (0..width as isize).contains(&sx) {
                    sum += weight * values[y * width + sx as usize];
                }
            }
            horizontal[y * width + x] = sum;
        }
    }
    let mut out = vec![0.0; values.len()];
    for y in 0..height {
        for x in 0..width {
            let mut sum = 0.0;
            for (k, weight) in weights.iter().enumerate() {
                let sy = y as isize + k as isize - half;
                if (0..height as isize).contains(&sy) {
                    sum += weight * horizontal[sy as usize * width + x];
                }
            }
            out[y * width + x] = sum;
        }
    }
    out
}

/// Structural similarity of two `width x height` RGB images.
pub fn ssim(rendered: &[[f32; 3]], target: &[[f32; 3]], width: usize, height: usize) -> f64 {
    let pixels = width * height;
    if pixels == 0 || rendered.len() < pixels || target.len() < pixels {
        return 0.0;
    }
    let weights = window();
    let mut total = 0.0;
    for channel in 0..3 {
        let a: Vec<f64> = rendered[..pixels]
            .iter()
            .map(|p| p[channel] as f64)
            .collect();
        let b: Vec<f64> = target[..pixels].iter().map(|p| p[channel] as f64).collect();
        let product =
            |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| p * q).collect::<Vec<_>>();
        let mu_a = blur(&a, width, height, &weights);
        let mu_b = blur(&b, width, height, &weights);
        let aa = blur(&product(&a, &a), width, height, &weights);
        let bb = blur(&product(&b, &b), width, height, &weights);
        let ab = blur(&product(&a, &b), width, height, &weights);
        for i in 0..pixels {
            let var_a = aa[i] - mu_a[i] * mu_a[i];
            let var_b = bb[i] - mu_b[i] * mu_b[i];
            let cov = ab[i] - mu_a[i] * mu_b[i];
            total += ((2.0 * mu_a[i] * mu_b[i] + C1) * (2.0 * cov + C2))
                / ((mu_a[i] * mu_a[i] + mu_b[i] * mu_b[i] + C1) * (var_a + var_b + C2));
        }
    }
    total / (3 * pixels) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise_image(pixels: usize, seed: u32) -> Vec<[f32; 3]> {
        let mut state = seed;
        (0..pixels)
            .map(|_| {
                let mut next = || {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (state >> 8) as f32 / (1u32 << 24) as f32
                };
                [next(), next(), next()]
            })
            .collect()
    }

    #[test]
    fn identical_images_are_perfect() {
        let image = noise_image(20 * 15, 3);
        assert_eq!(psnr(&image, &image), f64::INFINITY);
        assert!((ssim(&image, &image, 20, 15) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn psnr_of_a_known_error() {
        let a = vec![[0.5f32; 3]; 100];
        let b = vec![[0.6f32; 3]; 100];
        // MSE = 0.01 -> 20 dB.
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-4);
    }

    #[test]
    fn ssim_drops_with_noise_and_is_symmetric() {
        let a = noise_image(24 * 18, 1);
        let b = noise_image(24 * 18, 2);
        let s = ssim(&a, &b, 24, 18);
        assert!(s < 0.2, "unrelated noise images have SSIM {s}");
        assert!((s - ssim(&b, &a, 24, 18)).abs() < 1e-12);
    }
}
