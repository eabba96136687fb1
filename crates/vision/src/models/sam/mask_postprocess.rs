//! SAM's mask postprocessing in Rust: the decoder's 256 x 256 low-resolution logits to the
//! original image's size, as `SamOnnxModel.mask_postprocessing` does it (bilinear with
//! `align_corners=False` up to the encoder's frame, crop the unpadded region, bilinear to the
//! original size) for `longest_side_pad`, and straight to the original size for `stretch`.
//!
//! Needed because segment-anything's own ONNX export bakes the crop of its example image
//! (683 x 1024) into the graph: its `masks` have the right size and the wrong content for every
//! other aspect ratio. Both resizes are separable and linear, so each axis is one composed map
//! from output pixels to at most four low-resolution taps.

use crate::models::manifest::SamResize;

use super::preprocess::longest_side_size;

/// One output coordinate's taps into the low-resolution axis: (index, weight), up to four.
type Taps = Vec<(usize, f32)>;

/// torch's `upsample_bilinear2d` source taps (align_corners=False) for `output` of `out_len`
/// sampled from an axis of `in_len`.
fn linear_taps(output: usize, out_len: usize, in_len: usize) -> [(usize, f32); 2] {
    let scale = in_len as f32 / out_len as f32;
    let source = ((output as f32 + 0.5) * scale - 0.5).max(0.0);
    let lower = (source as usize).min(in_len - 1);
    let upper = (lower + 1).min(in_len - 1);
    let fraction = source - lower as f32;
    [(lower, 1.0 - fraction), (upper, fraction)]
}

/// The composed taps of one axis: low-res (`low_len`) -> encoder frame (`frame_len`), keep the
/// first `kept` values, -> `out_len`; or, without a frame, low-res -> `out_len` directly.
fn axis_taps(out_len: usize, low_len: usize, frame: Option<(usize, usize)>) -> Vec<Taps> {
    (0..out_len)
        .map(|output| match frame {
            None => linear_taps(output, out_len, low_len).to_vec(),
            Some((frame_len, kept)) => linear_taps(output, out_len, kept)
                .into_iter()
                .flat_map(|(middle, outer)| {
                    linear_taps(middle, frame_len, low_len)
                        .into_iter()
                        .map(move |(low, inner)| (low, outer * inner))
                })
                .collect(),
        })
        .collect()
}

/// Full-resolution logits (`height x width`, row-major) from one channel of low-resolution
/// logits (`side x side`), for an encoder that resized with `resize` to `image_size`.
pub fn upscale_low_res_logits(
    low_res: &[f32],
    side: usize,
    width: u32,
    height: u32,
    resize: SamResize,
    image_size: u32,
) -> Vec<f32> {
    let (width, height) = (width as usize, height as usize);
    let (x_frame, y_frame) = match resize {
        SamResize::Stretch => (None, None),
        SamResize::LongestSidePad => {
            let (kept_width, kept_height) =
                longest_side_size(width as u32, height as u32, image_size);
            let frame = image_size as usize;
            (
                Some((frame, kept_width as usize)),
                Some((frame, kept_height as usize)),
            )
        }
    };
    let x_taps = axis_taps(width, side, x_frame);
    let y_taps = axis_taps(height, side, y_frame);
    // Rows first: side x width, then columns: height x width.
    let mut rows = vec![0f32; side * width];
    for (row, out_row) in low_res.chunks_exact(side).zip(rows.chunks_exact_mut(width)) {
        for (value, taps) in out_row.iter_mut().zip(&x_taps) {
            *value = taps
                .iter()
                .map(|(index, weight)| row[*index] * weight)
                .sum();
        }
    }
    let mut output = vec![0f32; height * width];
    for (out_row, taps) in output.chunks_exact_mut(width).zip(&y_taps) {
        for (index, weight) in taps {
            let source = &rows[index * width..(index + 1) * width];
            for (value, source) in out_row.iter_mut().zip(source) {
                *value += source * weight;
            }
        }
    }
    output
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_logits_stay_constant_and_sizes_follow_the_original() {
        let low = vec![2.5f32; 16 * 16];
        for resize in [SamResize::LongestSidePad, SamResize::Stretch] {
            let full = upscale_low_res_logits(&low, 16, 30, 20, resize, 64);
            assert_eq!(full.len(), 600);
            assert!(full.iter().all(|value| (value - 2.5).abs() < 1e-5));
        }
    }

    #[test]
    fn the_padded_region_is_cropped_before_the_final_resize() {
        // A 4 x 4 low-res grid for a 16 x 16 frame; a 16 x 8 image keeps the top half of the
        // frame, so the bottom low-res rows (value 100) must not reach the output.
        let mut low = vec![0f32; 16];
        for value in &mut low[8..] {
            *value = 100.0;
        }
        let full = upscale_low_res_logits(&low, 4, 16, 8, SamResize::LongestSidePad, 16);
        assert_eq!(full.len(), 128);
        // The top 8 frame rows sample low-res rows 0 and 1 only, plus row 2 at the last one:
        // (7.5 * 4 / 16 - 0.5) = 1.375 -> between rows 1 and 2 only in the last frame row.
        let first_row_max = full[..16].iter().cloned().fold(f32::MIN, f32::max);
        assert!(first_row_max < 1e-5, "{first_row_max}");
        let stretched = upscale_low_res_logits(&low, 4, 16, 8, SamResize::Stretch, 16);
        assert!(stretched[7 * 16] > 50.0, "stretch keeps the whole grid");
    }

    #[test]
    fn taps_match_torchs_bilinear_indices() {
        // torch: upsample 4 -> 8, output 0 -> source -0.25 clamped to 0; output 3 -> 1.25.
        assert_eq!(linear_taps(0, 8, 4), [(0, 1.0), (1, 0.0)]);
        let [(lower, a), (upper, b)] = linear_taps(3, 8, 4);
        assert_eq!((lower, upper), (1, 2));
        assert!((a - 0.75).abs() < 1e-6 && (b - 0.25).abs() < 1e-6);
        assert_eq!(linear_taps(7, 8, 4)[0].0, 3);
    }
}
