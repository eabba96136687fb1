//! Whole images and instance masks remapped from a distorted camera to its pinhole twin.

use image::Rgb32FImage;
use rayon::prelude::*;

use super::{Lens, distort_pixel};
use crate::{InstanceMask, Intrinsics};

/// How an undistorted image was made: the share of output pixels whose source lay outside the
/// input (filled from the nearest edge pixel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RemapStats {
    pub outside_fraction: f64,
}

/// Source position (in pixel-index space: pixel `i`'s centre at `i`) of every output pixel of one
/// row, through `lens`.
fn source_row(intrinsics: &Intrinsics, lens: &Lens, row: u32, width: u32) -> Vec<[f32; 2]> {
    let v = f64::from(row) + 0.5;
    (0..width)
        .map(|column| {
            let [su, sv] = distort_pixel(intrinsics, lens, [f64::from(column) + 0.5, v]);
            [(su - 0.5) as f32, (sv - 0.5) as f32]
        })
        .collect()
}

fn is_outside([x, y]: [f32; 2], width: u32, height: u32) -> bool {
    !(x >= -0.5 && y >= -0.5 && x <= width as f32 - 0.5 && y <= height as f32 - 0.5)
}

/// `image` (taken with `intrinsics` and `lens`; its size must be the camera's) remapped to the
/// pinhole camera with the same intrinsics, sampling bilinearly; rows in parallel.
pub fn undistort_rgb(
    image: &Rgb32FImage,
    intrinsics: &Intrinsics,
    lens: &Lens,
) -> (Rgb32FImage, RemapStats) {
    let (width, height) = image.dimensions();
    if width == 0 || height == 0 {
        return (
            image.clone(),
            RemapStats {
                outside_fraction: 0.0,
            },
        );
    }
    let source = image.as_raw();
    let max_x = (width - 1) as f32;
    let max_y = (height - 1) as f32;
    let mut output = Rgb32FImage::new(width, height);
    let outside: usize = output
        .par_chunks_mut(width as usize * 3)
        .enumerate()
        .map(|(row, out_row)| {
            let mut outside = 0;
            for (column, position) in source_row(intrinsics, lens, row as u32, width)
                .into_iter()
                .enumerate()
            {
                outside += usize::from(is_outside(position, width, height));
                let x = position[0].clamp(0.0, max_x);
                let y = position[1].clamp(0.0, max_y);
                let (x0, y0) = (x.floor(), y.floor());
                let (tx, ty) = (x - x0, y - y0);
                let (x0, y0) = (x0 as usize, y0 as usize);
                let x1 = (x0 + 1).min(width as usize - 1);
                let y1 = (y0 + 1).min(height as usize - 1);
                let at = |xx: usize, yy: usize| (yy * width as usize + xx) * 3;
                let (a, b, c, d) = (at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1));
                for channel in 0..3 {
                    let top = source[a + channel] * (1.0 - tx) + source[b + channel] * tx;
                    let bottom = source[c + channel] * (1.0 - tx) + source[d + channel] * tx;
                    out_row[column * 3 + channel] = top * (1.0 - ty) + bottom * ty;
                }
            }
            outside
        })
        .sum();
    let stats = RemapStats {
        outside_fraction: outside as f64 / (f64::from(width) * f64::from(height)).max(1.0),
    };
    (output, stats)
}

/// `mask` (taken with `intrinsics` and `lens`) remapped to the pinhole camera with the same
/// intrinsics, taking the nearest pixel so instance ids are never blended.
pub fn undistort_mask(
    mask: &InstanceMask,
    intrinsics: &Intrinsics,
    lens: &Lens,
) -> (InstanceMask, RemapStats) {
    let (width, height) = (mask.width, mask.height);
    if width == 0 || height == 0 || mask.ids.len() != width as usize * height as usize {
        return (
            mask.clone(),
            RemapStats {
                outside_fraction: 0.0,
            },
        );
    }
    let mut ids = vec![0u32; mask.ids.len()];
    let outside: usize = ids
        .par_chunks_mut(width as usize)
        .enumerate()
        .map(|(row, out_row)| {
            let mut outside = 0;
            for (out, position) in out_row
                .iter_mut()
                .zip(source_row(intrinsics, lens, row as u32, width))
            {
                outside += usize::from(is_outside(position, width, height));
                let x = (position[0] + 0.5).floor().clamp(0.0, (width - 1) as f32) as usize;
                let y = (position[1] + 0.5).floor().clamp(0.0, (height - 1) as f32) as usize;
                *out = mask.ids[y * width as usize + x];
            }
            outside
        })
        .sum();
    let stats = RemapStats {
        outside_fraction: outside as f64 / (f64::from(width) * f64::from(height)).max(1.0),
    };
    (InstanceMask { width, height, ids }, stats)
}
