//! Nearest-neighbour mask resizing, so that predictions rendered at training resolution can be
//! compared with ground truth at full photo resolution.

use std::borrow::Cow;

use segsplat_vision::segment::mask::BitMask;

/// `mask` resized to `width x height` by nearest neighbour, sampling the source at each target
/// pixel's centre (the convention of the pipeline's mask downsampling, so a round trip through
/// both lines pixels up).
pub fn resize_nearest(mask: &BitMask, width: u32, height: u32) -> BitMask {
    let mut resized = BitMask::new(width, height);
    if mask.width() == 0 || mask.height() == 0 || width == 0 || height == 0 {
        return resized;
    }
    let source_x = source_indices(width, mask.width());
    // The mapping is monotone, so each source column covers one contiguous run of target
    // columns: `first_target[s]..first_target[s + 1]`. That lets a row be copied as spans.
    let first_target: Vec<u32> = (0..=mask.width())
        .map(|s| source_x.partition_point(|&x| x < s) as u32)
        .collect();
    for (y, source_y) in source_indices(height, mask.height())
        .into_iter()
        .enumerate()
    {
        let mut run: Option<(u32, u32)> = None;
        for column in mask.row_set_columns(source_y) {
            run = match run {
                Some((start, end)) if end + 1 == column => Some((start, column)),
                Some((start, end)) => {
                    let span = first_target[start as usize]..first_target[end as usize + 1];
                    resized.set_row_span(y as u32, span, true);
                    Some((column, column))
                }
                None => Some((column, column)),
            };
        }
        if let Some((start, end)) = run {
            let span = first_target[start as usize]..first_target[end as usize + 1];
            resized.set_row_span(y as u32, span, true);
        }
    }
    resized
}

/// `mask` at `width x height`, borrowed when it already is that size (the common case for
/// ground truth and oracle candidates rendered at full resolution).
pub(crate) fn at_size(mask: &BitMask, width: u32, height: u32) -> Cow<'_, BitMask> {
    if (mask.width(), mask.height()) == (width, height) {
        Cow::Borrowed(mask)
    } else {
        Cow::Owned(resize_nearest(mask, width, height))
    }
}

/// For each of `target` pixels along one axis, the source pixel whose area holds its centre.
fn source_indices(target: u32, source: u32) -> Vec<u32> {
    (0..target)
        .map(|t| {
            let centre = (f64::from(t) + 0.5) * f64::from(source) / f64::from(target);
            (centre as u32).min(source - 1)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn per_pixel_reference(mask: &BitMask, width: u32, height: u32) -> BitMask {
        let mut out = BitMask::new(width, height);
        for y in 0..height {
            for x in 0..width {
                let sx = ((x as f64 + 0.5) * mask.width() as f64 / width as f64) as u32;
                let sy = ((y as f64 + 0.5) * mask.height() as f64 / height as f64) as u32;
                out.set(
                    x,
                    y,
                    mask.get(sx.min(mask.width() - 1), sy.min(mask.height() - 1)),
                );
            }
        }
        out
    }

    #[test]
    fn upsampling_by_two_doubles_each_pixel() {
        let small = BitMask::from_bools(2, 2, &[true, false, false, true]).expect("4 values");
        let big = resize_nearest(&small, 4, 4);
        #[rustfmt::skip]
        let expected = [
            true, true, false, false,
            true, true, false, false,
            false, false, true, true,
            false, false, true, true,
        ];
        assert_eq!(big.to_bools(), expected);
        assert_eq!(big.area(), 8);
    }

    #[test]
    fn downsampling_samples_pixel_centres() {
        let mut mask = BitMask::new(4, 1);
        mask.set(1, 0, true);
        mask.set(2, 0, true);
        // Target pixel 0 samples source x = 1, target pixel 1 samples source x = 3.
        assert_eq!(resize_nearest(&mask, 2, 1).to_bools(), vec![true, false]);
    }

    #[test]
    fn span_copy_matches_per_pixel_sampling_across_word_boundaries() {
        let mut mask = BitMask::new(70, 9);
        for (x, y) in [(0, 0), (1, 0), (63, 1), (64, 1), (65, 1), (69, 8), (30, 4)] {
            mask.set(x, y, true);
        }
        mask.set_row_span(5, 10..67, true);
        for (width, height) in [(140, 18), (213, 31), (35, 4), (70, 9), (129, 7)] {
            assert_eq!(
                resize_nearest(&mask, width, height),
                per_pixel_reference(&mask, width, height),
                "{width}x{height}"
            );
        }
    }

    #[test]
    fn same_size_is_borrowed_and_empty_sizes_are_empty() {
        let mask = BitMask::from_bools(2, 1, &[true, false]).expect("2 values");
        assert!(matches!(at_size(&mask, 2, 1), Cow::Borrowed(_)));
        assert_eq!(resize_nearest(&BitMask::new(0, 0), 3, 3).area(), 0);
        assert_eq!(resize_nearest(&mask, 0, 5).width(), 0);
    }
}
