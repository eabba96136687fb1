//! JPEG frames decoded at the size they will be used (issue 19 item 7): the DCT can produce
//! 1/2, 1/4 or 1/8 of the full size directly, so a 11000 x 11000 photo trained at
//! `max_resolution` 256 never exists in memory at full size. The `image` crate's decoder
//! (zune-jpeg) cannot scale; `jpeg-decoder` can.
//!
//! Baseline JPEGs decode row by row, so memory follows the scaled size. Progressive JPEGs keep
//! every DCT coefficient until the last scan (about 2 bytes per pixel and channel at full size)
//! whatever the output scale; they still skip the full-size pixel buffer.

use std::io::{BufReader, Read};

use image::{DynamicImage, GrayImage, RgbImage};
use jpeg_decoder::{Decoder, PixelFormat};

/// A JPEG decoded at a reduced size, and the full size its header declares.
pub struct ScaledJpeg {
    pub image: DynamicImage,
    pub full_size: (u32, u32),
}

/// Decodes the JPEG in `reader` at the smallest DCT scale at least `target` in one axis;
/// `Ok(None)` when no scale below 1 fits (or the pixel format is one `image` converts better:
/// CMYK, 16-bit), so the caller decodes at full size as before. Errors are decoder messages.
pub fn decode_scaled(reader: impl Read, target: (u32, u32)) -> Result<Option<ScaledJpeg>, String> {
    let mut decoder = Decoder::new(BufReader::new(reader));
    decoder.read_info().map_err(|error| error.to_string())?;
    let Some(info) = decoder.info() else {
        return Ok(None);
    };
    let full_size = (u32::from(info.width), u32::from(info.height));
    if !matches!(info.pixel_format, PixelFormat::L8 | PixelFormat::RGB24) {
        return Ok(None);
    }
    let clamp = |side: u32| u16::try_from(side.max(1)).unwrap_or(u16::MAX);
    let (width, height) = decoder
        .scale(clamp(target.0), clamp(target.1))
        .map_err(|error| error.to_string())?;
    let size = (u32::from(width), u32::from(height));
    if size == full_size {
        return Ok(None);
    }
    let pixels = decoder.decode().map_err(|error| error.to_string())?;
    let image = match info.pixel_format {
        PixelFormat::L8 => GrayImage::from_raw(size.0, size.1, pixels).map(DynamicImage::from),
        _ => RgbImage::from_raw(size.0, size.1, pixels).map(DynamicImage::from),
    }
    .ok_or_else(|| "decoded pixels do not match the image size".to_string())?;
    Ok(Some(ScaledJpeg { image, full_size }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jpeg(width: u32, height: u32) -> Vec<u8> {
        let image = RgbImage::from_fn(width, height, |x, y| {
            image::Rgb([(x * 255 / width) as u8, (y * 255 / height) as u8, 128])
        });
        let mut bytes = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
            .encode_image(&image)
            .unwrap();
        bytes
    }

    #[test]
    fn decodes_at_the_smallest_scale_that_covers_the_target() {
        let bytes = jpeg(800, 600);
        let scaled = decode_scaled(bytes.as_slice(), (100, 75)).unwrap().unwrap();
        assert_eq!(scaled.full_size, (800, 600));
        assert_eq!((scaled.image.width(), scaled.image.height()), (100, 75));
        let scaled = decode_scaled(bytes.as_slice(), (256, 192))
            .unwrap()
            .unwrap();
        assert_eq!((scaled.image.width(), scaled.image.height()), (400, 300));
        // The pixels are the picture's, not noise: the mean red follows the x ramp.
        let rgb = scaled.image.to_rgb8();
        let left = rgb.get_pixel(10, 150)[0];
        let right = rgb.get_pixel(390, 150)[0];
        assert!(left < 40 && right > 120, "{left} {right}");
    }

    #[test]
    fn full_size_targets_fall_back_to_the_usual_decoder() {
        let bytes = jpeg(64, 48);
        assert!(decode_scaled(bytes.as_slice(), (64, 48)).unwrap().is_none());
        assert!(decode_scaled(&b"not a jpeg"[..], (8, 8)).is_err());
    }
}
