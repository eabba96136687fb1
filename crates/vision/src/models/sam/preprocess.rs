//! The SAM-family encoder input and the map from image pixels to the encoder frame.
//!
//! - `longest_side_pad` (SAM 1, MobileSAM, as `SamPredictor.set_image`): the longest side to
//!   `image_size` with Pillow bilinear on the 8-bit image (sizes rounded `int(x * s + 0.5)`),
//!   normalised with mean/std in 0..255, zero-padded bottom/right.
//! - `stretch` (SAM 2.1, as `SAM2Transforms`): to 0..1 floats, resized to `image_size` square
//!   with antialiased bilinear in floating point, normalised.

use image::RgbImage;

use crate::models::manifest::{Interpolation, SamEncoderPreprocess, SamResize};
use crate::models::resample::{Filter, resize_planar_f32, resize_rgb8};

/// The encoder input (`3 x S x S`) and how to map image pixels into that frame.
#[derive(Debug, Clone)]
pub struct EncoderInput {
    pub pixels: Vec<f32>,
    /// Multiply image x / y by these to get encoder-frame coordinates.
    pub coordinate_scale: [f32; 2],
}

fn filter_of(interpolation: Interpolation) -> Filter {
    match interpolation {
        Interpolation::Bicubic => Filter::Bicubic,
        Interpolation::Bilinear => Filter::Bilinear,
    }
}

pub fn sam_encoder_input(image: &RgbImage, preprocess: &SamEncoderPreprocess) -> EncoderInput {
    let size = preprocess.image_size;
    let (width, height) = image.dimensions();
    let plane = size as usize * size as usize;
    let filter = filter_of(preprocess.interpolation);
    let normalise = |value_0_to_1: f32, channel: usize| {
        (value_0_to_1 * preprocess.pixel_scale - preprocess.mean[channel]) / preprocess.std[channel]
    };
    match preprocess.resize {
        SamResize::LongestSidePad => {
            let (new_width, new_height) = longest_side_size(width, height, size);
            let resized = resize_rgb8(image, new_width, new_height, filter);
            let mut pixels = vec![0f32; 3 * plane];
            for (x, y, pixel) in resized.enumerate_pixels() {
                let index = y as usize * size as usize + x as usize;
                for channel in 0..3 {
                    pixels[channel * plane + index] =
                        normalise(f32::from(pixel.0[channel]) / 255.0, channel);
                }
            }
            EncoderInput {
                pixels,
                // SAM's ResizeLongestSide.apply_coords scales by the rounded new size.
                coordinate_scale: [
                    new_width as f32 / width as f32,
                    new_height as f32 / height as f32,
                ],
            }
        }
        SamResize::Stretch => {
            let (w, h) = (width as usize, height as usize);
            let mut planes = vec![0f32; 3 * w * h];
            for (x, y, pixel) in image.enumerate_pixels() {
                for channel in 0..3 {
                    planes[(channel * h + y as usize) * w + x as usize] =
                        f32::from(pixel.0[channel]) / 255.0;
                }
            }
            let mut pixels =
                resize_planar_f32(&planes, 3, w, h, size as usize, size as usize, filter);
            for channel in 0..3 {
                for value in &mut pixels[channel * plane..(channel + 1) * plane] {
                    *value = normalise(*value, channel);
                }
            }
            EncoderInput {
                pixels,
                coordinate_scale: [size as f32 / width as f32, size as f32 / height as f32],
            }
        }
    }
}

/// SAM's `ResizeLongestSide.get_preprocess_shape`: `int(side * target / longest + 0.5)`.
pub fn longest_side_size(width: u32, height: u32, target: u32) -> (u32, u32) {
    let scale = f64::from(target) / f64::from(width.max(height).max(1));
    let round = |side: u32| ((f64::from(side) * scale + 0.5) as u32).max(1);
    (round(width), round(height))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn preprocess(resize: SamResize) -> SamEncoderPreprocess {
        SamEncoderPreprocess {
            image_size: 64,
            resize,
            interpolation: Interpolation::Bilinear,
            pixel_scale: 255.0,
            mean: [100.0, 100.0, 100.0],
            std: [50.0, 50.0, 50.0],
        }
    }

    #[test]
    fn longest_side_pads_bottom_right_with_zeros() {
        let image = RgbImage::from_pixel(32, 16, image::Rgb([200, 200, 200]));
        let input = sam_encoder_input(&image, &preprocess(SamResize::LongestSidePad));
        assert_eq!(input.coordinate_scale, [2.0, 2.0]);
        assert_eq!(input.pixels.len(), 3 * 64 * 64);
        assert!((input.pixels[0] - 2.0).abs() < 1e-6); // (200 - 100) / 50
        assert!((input.pixels[31 * 64 + 63] - 2.0).abs() < 1e-6);
        assert_eq!(input.pixels[32 * 64], 0.0);
    }

    #[test]
    fn stretch_fills_the_square() {
        let image = RgbImage::from_pixel(32, 16, image::Rgb([200, 200, 200]));
        let input = sam_encoder_input(&image, &preprocess(SamResize::Stretch));
        assert_eq!(input.coordinate_scale, [2.0, 4.0]);
        assert!(input.pixels.iter().all(|value| (value - 2.0).abs() < 1e-4));
    }

    #[test]
    fn preprocess_shape_rounds_like_sam() {
        assert_eq!(longest_side_size(1000, 660, 1024), (1024, 676));
        assert_eq!(longest_side_size(160, 120, 1024), (1024, 768));
    }
}
