//! Bounds on decoded image size, checked from image headers before anything is decoded: a few
//! kilobytes of compressed PNG can claim 11000x11000 pixels, and validation (and every job) would
//! decode them at full size. Masks must match their frame's size, so frames bound them too.

use super::images::image_size;
use super::{Scene, SceneError};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelLimits {
    /// Most pixels one image may have (width x height).
    pub max_image_pixels: u64,
    /// Most pixels all of a dataset's frame images may have together.
    pub max_total_pixels: u64,
}

impl Default for PixelLimits {
    /// 100 megapixels per image (above today's 48-50 MP phone and 61 MP camera sensors) and 20
    /// gigapixels in all (2000 frames of 10 MP).
    fn default() -> Self {
        Self {
            max_image_pixels: 100_000_000,
            max_total_pixels: 20_000_000_000,
        }
    }
}

/// Reads every frame image's header and fails on the first image over the per-image limit, or
/// when the total passes its limit; the message names the image, its size and the limit.
pub fn check_pixel_limits(scene: &Scene, limits: &PixelLimits) -> Result<(), SceneError> {
    let mut total: u64 = 0;
    for frame in &scene.frames {
        let (width, height) = image_size(&scene.root, &frame.image_path)?;
        let pixels = u64::from(width) * u64::from(height);
        let file = frame.image_path.display().to_string();
        if pixels > limits.max_image_pixels {
            return Err(SceneError::TooManyPixels {
                file,
                message: format!(
                    "image is {width}x{height} = {pixels} pixels, over the limit of {} pixels \
                     per image (limits.max_image_pixels)",
                    limits.max_image_pixels
                ),
            });
        }
        total = total.saturating_add(pixels);
        if total > limits.max_total_pixels {
            return Err(SceneError::TooManyPixels {
                file,
                message: format!(
                    "the frames up to this one hold {total} pixels, over the limit of {} pixels \
                     per upload (limits.max_total_pixels)",
                    limits.max_total_pixels
                ),
            });
        }
    }
    Ok(())
}
