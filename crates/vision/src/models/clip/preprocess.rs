//! open_clip's image transform for evaluation: resize the shortest side to `image_size` (Pillow
//! bicubic with antialiasing), centre crop `image_size` square, scale to 0..1, normalise.

use image::RgbImage;

use crate::models::manifest::{ClipImagePreprocess, Interpolation};
use crate::models::resample::{Filter, resize_rgb8};

/// `3 x size x size` planar float pixels, ready for `pixel_values`.
pub fn clip_pixel_values(image: &RgbImage, preprocess: &ClipImagePreprocess) -> Vec<f32> {
    let size = preprocess.image_size;
    let (width, height) = image.dimensions();
    let (resized_width, resized_height) = shortest_side_size(width, height, size);
    let filter = match preprocess.interpolation {
        Interpolation::Bicubic => Filter::Bicubic,
        Interpolation::Bilinear => Filter::Bilinear,
    };
    let resized = resize_rgb8(image, resized_width, resized_height, filter);
    let left = centre_crop_offset(resized_width, size);
    let top = centre_crop_offset(resized_height, size);
    let pixels = size as usize * size as usize;
    let mut values = vec![0f32; 3 * pixels];
    for y in 0..size {
        for x in 0..size {
            // A crop larger than the image pads with black, like torchvision's CenterCrop.
            let (source_x, source_y) = (x as i64 + left, y as i64 + top);
            let inside = source_x >= 0
                && source_y >= 0
                && source_x < i64::from(resized_width)
                && source_y < i64::from(resized_height);
            let pixel = if inside {
                resized.get_pixel(source_x as u32, source_y as u32).0
            } else {
                [0, 0, 0]
            };
            let index = y as usize * size as usize + x as usize;
            for channel in 0..3 {
                let scaled = f32::from(pixel[channel]) / 255.0 * preprocess.pixel_scale;
                values[channel * pixels + index] =
                    (scaled - preprocess.mean[channel]) / preprocess.std[channel];
            }
        }
    }
    values
}

/// torchvision `Resize(size)` with an int: the shorter side becomes `size`, the longer keeps the
/// aspect ratio, truncated (`int(size * long / short)`).
pub fn shortest_side_size(width: u32, height: u32, size: u32) -> (u32, u32) {
    let (short, long) = (width.min(height).max(1), width.max(height));
    let new_long = (u64::from(size) * u64::from(long) / u64::from(short)) as u32;
    if width <= height {
        (size, new_long)
    } else {
        (new_long, size)
    }
}

/// torchvision `CenterCrop`: `int(round((length - crop) / 2))`, Python's round-half-to-even.
fn centre_crop_offset(length: u32, crop: u32) -> i64 {
    let twice = i64::from(length) - i64::from(crop);
    let half = twice.div_euclid(2);
    if twice.rem_euclid(2) == 1 && half.rem_euclid(2) == 1 {
        // x.5 rounds to the even neighbour: half is odd, so go up.
        half + 1
    } else {
        half
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shortest_side_keeps_aspect_with_truncation() {
        assert_eq!(shortest_side_size(300, 200, 224), (336, 224));
        assert_eq!(shortest_side_size(97, 61, 224), (356, 224));
        assert_eq!(shortest_side_size(61, 97, 224), (224, 356));
        assert_eq!(shortest_side_size(224, 224, 224), (224, 224));
    }

    #[test]
    fn centre_crop_rounds_half_to_even() {
        assert_eq!(centre_crop_offset(336, 224), 56);
        assert_eq!(centre_crop_offset(225, 224), 0); // round(0.5) = 0
        assert_eq!(centre_crop_offset(227, 224), 2); // round(1.5) = 2
        assert_eq!(centre_crop_offset(229, 224), 2); // round(2.5) = 2
        assert_eq!(centre_crop_offset(220, 224), -2);
    }
}
