//! How rendered masks leave the service: an 8-bit PNG (255 inside) or COCO RLE with compressed
//! counts (what pycocotools' `mask.decode` reads).

use image::ImageEncoder;
use serde::{Deserialize, Serialize};

use super::ServingError;
use segsplat_vision::segment::BitMask;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskFormat {
    Png,
    #[default]
    CocoRle,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EncodedMaskData {
    Png(Vec<u8>),
    /// pycocotools' compressed counts string.
    CocoRle(String),
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EncodedMask {
    pub width: u32,
    pub height: u32,
    pub data: EncodedMaskData,
}

pub fn encode_mask(mask: &BitMask, format: MaskFormat) -> Result<EncodedMask, ServingError> {
    let data = match format {
        MaskFormat::Png => EncodedMaskData::Png(mask_png(mask)?),
        MaskFormat::CocoRle => EncodedMaskData::CocoRle(mask.to_coco_rle().counts),
    };
    Ok(EncodedMask {
        width: mask.width(),
        height: mask.height(),
        data,
    })
}

/// Single-channel 8-bit PNG, 255 inside the mask and 0 outside.
pub fn mask_png(mask: &BitMask) -> Result<Vec<u8>, ServingError> {
    let (width, height) = (mask.width(), mask.height());
    let mut pixels = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height {
        pixels.extend((0..width).map(|x| if mask.get(x, y) { 255u8 } else { 0 }));
    }
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(&pixels, width, height, image::ExtendedColorType::L8)
        .map_err(|error| ServingError::Encoding(error.to_string()))?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use segsplat_vision::segment::CompressedRle;

    fn mask() -> BitMask {
        let mut mask = BitMask::new(7, 5);
        mask.set_row_span(1, 2..6, true);
        mask.set(0, 4, true);
        mask
    }

    #[test]
    fn png_decodes_to_the_same_mask() {
        let bytes = mask_png(&mask()).unwrap();
        let decoded = image::load_from_memory(&bytes).unwrap().into_luma8();
        assert_eq!(decoded.dimensions(), (7, 5));
        for (x, y, pixel) in decoded.enumerate_pixels() {
            assert_eq!(pixel.0[0] == 255, mask().get(x, y), "({x}, {y})");
            assert!(pixel.0[0] == 0 || pixel.0[0] == 255);
        }
    }

    #[test]
    fn rle_decodes_to_the_same_mask() {
        let encoded = encode_mask(&mask(), MaskFormat::CocoRle).unwrap();
        let EncodedMaskData::CocoRle(counts) = encoded.data else {
            panic!("expected RLE");
        };
        let back = BitMask::from_coco_rle(&CompressedRle {
            size: [5, 7],
            counts,
        })
        .unwrap();
        assert_eq!(back, mask());
    }
}
