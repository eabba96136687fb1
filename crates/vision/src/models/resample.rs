//! Image resizing as Pillow does it (`Image.resize`, which torchvision calls for PIL images):
//! separable convolution, horizontal pass then vertical, with the filter's support scaled by the
//! downscale factor (antialiasing) and weights renormalised at the borders. The 8-bit variant
//! reproduces Pillow's fixed-point arithmetic and per-pass rounding, so CLIP and SAM
//! preprocessing match the Python pipelines to the last bit; the float variant matches
//! torchvision's antialiased tensor resize (SAM 2.1 resizes a float tensor).

use image::RgbImage;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filter {
    /// Pillow's bicubic (a = -0.5, support 2).
    Bicubic,
    /// Triangle (support 1).
    Bilinear,
}

impl Filter {
    fn support(self) -> f64 {
        match self {
            Filter::Bicubic => 2.0,
            Filter::Bilinear => 1.0,
        }
    }

    fn weight(self, x: f64) -> f64 {
        let x = x.abs();
        match self {
            Filter::Bicubic => {
                const A: f64 = -0.5;
                if x < 1.0 {
                    ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
                } else if x < 2.0 {
                    (((x - 5.0) * x + 8.0) * x - 4.0) * A
                } else {
                    0.0
                }
            }
            Filter::Bilinear => {
                if x < 1.0 {
                    1.0 - x
                } else {
                    0.0
                }
            }
        }
    }
}

/// For each output index, the first input index and the normalised weights
/// (Pillow's `precompute_coeffs`).
struct Coefficients {
    first: Vec<usize>,
    weights: Vec<Vec<f64>>,
}

fn coefficients(in_size: usize, out_size: usize, filter: Filter) -> Coefficients {
    let scale = in_size as f64 / out_size as f64;
    let filter_scale = scale.max(1.0);
    let support = filter.support() * filter_scale;
    let mut first = Vec::with_capacity(out_size);
    let mut weights = Vec::with_capacity(out_size);
    for out_index in 0..out_size {
        let center = (out_index as f64 + 0.5) * scale;
        // Pillow rounds with `(int)(x + 0.5)`, i.e. truncation toward zero.
        let min = ((center - support + 0.5) as i64).max(0) as usize;
        let max = ((center + support + 0.5) as i64).min(in_size as i64).max(0) as usize;
        let mut row: Vec<f64> = (min..max)
            .map(|input| filter.weight((input as f64 - center + 0.5) / filter_scale))
            .collect();
        let total: f64 = row.iter().sum();
        if total != 0.0 {
            for weight in &mut row {
                *weight /= total;
            }
        }
        first.push(min);
        weights.push(row);
    }
    Coefficients { first, weights }
}

/// Pillow's 8-bit precision: weights in fixed point with 22 fractional bits.
const PRECISION_BITS: u32 = 32 - 8 - 2;

fn fixed_point(weights: &[Vec<f64>]) -> Vec<Vec<i64>> {
    let one = f64::from(1u32 << PRECISION_BITS);
    weights
        .iter()
        .map(|row| {
            row.iter()
                .map(|weight| {
                    if *weight < 0.0 {
                        (-0.5 + weight * one) as i64
                    } else {
                        (0.5 + weight * one) as i64
                    }
                })
                .collect()
        })
        .collect()
}

fn clip_to_u8(accumulator: i64) -> u8 {
    (accumulator >> PRECISION_BITS).clamp(0, 255) as u8
}

/// One output pixel of a pass: Pillow's rounding start (one half), the weighted taps, clipping.
fn convolve_fixed(weights: &[i64], pixel_at_tap: impl Fn(usize) -> [u8; 3]) -> [u8; 3] {
    let mut sums = [1i64 << (PRECISION_BITS - 1); 3];
    for (tap, weight) in weights.iter().enumerate() {
        let pixel = pixel_at_tap(tap);
        for (sum, value) in sums.iter_mut().zip(pixel) {
            *sum += i64::from(value) * weight;
        }
    }
    sums.map(clip_to_u8)
}

/// Resizes an RGB8 image exactly like Pillow's `Image.resize((width, height), filter)`.
pub fn resize_rgb8(image: &RgbImage, width: u32, height: u32, filter: Filter) -> RgbImage {
    let (in_width, in_height) = image.dimensions();
    let mut current = image.clone();
    if width != in_width {
        let coefficients = coefficients(in_width as usize, width as usize, filter);
        let fixed = fixed_point(&coefficients.weights);
        let mut out = RgbImage::new(width, in_height);
        for y in 0..in_height {
            for (x, (first, weights)) in coefficients.first.iter().zip(&fixed).enumerate() {
                let value =
                    convolve_fixed(weights, |tap| current.get_pixel((first + tap) as u32, y).0);
                out.put_pixel(x as u32, y, image::Rgb(value));
            }
        }
        current = out;
    }
    if height != in_height {
        let coefficients = coefficients(in_height as usize, height as usize, filter);
        let fixed = fixed_point(&coefficients.weights);
        let mut out = RgbImage::new(width, height);
        for (y, (first, weights)) in coefficients.first.iter().zip(&fixed).enumerate() {
            for x in 0..width {
                let value =
                    convolve_fixed(weights, |tap| current.get_pixel(x, (first + tap) as u32).0);
                out.put_pixel(x, y as u32, image::Rgb(value));
            }
        }
        current = out;
    }
    current
}

/// Resizes a planar float image (`channels x height x width`) with the same filter in floating
/// point and no rounding, as torchvision's antialiased resize of a float tensor does.
pub fn resize_planar_f32(
    planes: &[f32],
    channels: usize,
    in_width: usize,
    in_height: usize,
    width: usize,
    height: usize,
    filter: Filter,
) -> Vec<f32> {
    let horizontal = coefficients(in_width, width, filter);
    let vertical = coefficients(in_height, height, filter);
    let mut rows = vec![0f32; channels * in_height * width];
    for channel in 0..channels {
        for y in 0..in_height {
            let source = &planes[(channel * in_height + y) * in_width..][..in_width];
            let target = &mut rows[(channel * in_height + y) * width..][..width];
            for (x, value) in target.iter_mut().enumerate() {
                let first = horizontal.first[x];
                *value = horizontal.weights[x]
                    .iter()
                    .enumerate()
                    .map(|(tap, weight)| f64::from(source[first + tap]) * weight)
                    .sum::<f64>() as f32;
            }
        }
    }
    let mut out = vec![0f32; channels * height * width];
    for channel in 0..channels {
        for y in 0..height {
            let first = vertical.first[y];
            for x in 0..width {
                out[(channel * height + y) * width + x] = vertical.weights[y]
                    .iter()
                    .enumerate()
                    .map(|(tap, weight)| {
                        f64::from(rows[(channel * in_height + first + tap) * width + x]) * weight
                    })
                    .sum::<f64>() as f32;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_size_is_identity() {
        let image = RgbImage::from_fn(5, 4, |x, y| image::Rgb([x as u8 * 40, y as u8 * 50, 7]));
        assert_eq!(resize_rgb8(&image, 5, 4, Filter::Bicubic), image);
    }

    #[test]
    fn uniform_images_stay_uniform() {
        let image = RgbImage::from_pixel(37, 23, image::Rgb([200, 10, 99]));
        for (width, height) in [(11, 7), (80, 50), (37, 100)] {
            for filter in [Filter::Bicubic, Filter::Bilinear] {
                let resized = resize_rgb8(&image, width, height, filter);
                assert!(resized.pixels().all(|pixel| pixel.0 == [200, 10, 99]));
            }
        }
        let planes = vec![0.25f32; 3 * 23 * 37];
        let resized = resize_planar_f32(&planes, 3, 37, 23, 64, 64, Filter::Bilinear);
        assert!(resized.iter().all(|value| (value - 0.25).abs() < 1e-6));
    }

    #[test]
    fn weights_are_normalised_and_widen_when_downscaling() {
        let up = coefficients(10, 20, Filter::Bicubic);
        let down = coefficients(40, 10, Filter::Bicubic);
        for row in up.weights.iter().chain(&down.weights) {
            assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        assert!(up.weights[10].len() <= 5);
        assert!(down.weights[5].len() >= 16);
    }
}
