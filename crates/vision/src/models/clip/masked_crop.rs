//! The crop CLIP sees for one mask: the image multiplied by the mask (black outside), cut to the
//! mask's bounding box and centred on a black square so the encoder's resize keeps the aspect.

use image::RgbImage;

use crate::models::error::ModelError;

/// `mask` is row-major, one entry per pixel of `image`. Returns `Ok(None)` for an empty mask.
pub fn masked_square_crop(image: &RgbImage, mask: &[bool]) -> Result<Option<RgbImage>, ModelError> {
    let (width, height) = image.dimensions();
    if mask.len() != width as usize * height as usize {
        return Err(ModelError::Input(format!(
            "mask has {} entries, the image is {width} x {height}",
            mask.len()
        )));
    }
    let Some((left, top, right, bottom)) = mask_bounds(mask, width) else {
        return Ok(None);
    };
    let (box_width, box_height) = (right - left + 1, bottom - top + 1);
    let side = box_width.max(box_height);
    let (offset_x, offset_y) = ((side - box_width) / 2, (side - box_height) / 2);
    let mut square = RgbImage::new(side, side);
    for y in top..=bottom {
        for x in left..=right {
            if mask[(y * width + x) as usize] {
                square.put_pixel(
                    x - left + offset_x,
                    y - top + offset_y,
                    *image.get_pixel(x, y),
                );
            }
        }
    }
    Ok(Some(square))
}

/// Inclusive `(left, top, right, bottom)` of the set pixels.
fn mask_bounds(mask: &[bool], width: u32) -> Option<(u32, u32, u32, u32)> {
    let mut bounds: Option<(u32, u32, u32, u32)> = None;
    for (index, _) in mask.iter().enumerate().filter(|(_, set)| **set) {
        let (x, y) = (index as u32 % width, index as u32 / width);
        bounds = Some(match bounds {
            None => (x, y, x, y),
            Some((l, t, r, b)) => (l.min(x), t.min(y), r.max(x), b.max(y)),
        });
    }
    bounds
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_keeps_masked_pixels_centred_on_black() {
        let image = RgbImage::from_fn(6, 5, |x, y| image::Rgb([10 + x as u8, 20 + y as u8, 200]));
        // A 3 wide x 1 tall mask at row 2, columns 1..=3, minus its middle pixel.
        let mut mask = vec![false; 30];
        mask[2 * 6 + 1] = true;
        mask[2 * 6 + 3] = true;
        let crop = masked_square_crop(&image, &mask).unwrap().unwrap();
        assert_eq!(crop.dimensions(), (3, 3));
        assert_eq!(crop.get_pixel(0, 1).0, [11, 22, 200]);
        assert_eq!(crop.get_pixel(1, 1).0, [0, 0, 0]);
        assert_eq!(crop.get_pixel(2, 1).0, [13, 22, 200]);
        for x in 0..3 {
            assert_eq!(crop.get_pixel(x, 0).0, [0, 0, 0]);
            assert_eq!(crop.get_pixel(x, 2).0, [0, 0, 0]);
        }
    }

    #[test]
    fn empty_masks_and_wrong_sizes() {
        let image = RgbImage::new(4, 4);
        assert!(masked_square_crop(&image, &[false; 16]).unwrap().is_none());
        assert!(masked_square_crop(&image, &[true; 15]).is_err());
    }
}
