//! A compact binary mask: one bit per pixel in `u64` words, row-major, each row padded to whole
//! words so that a rectangle of the image is a rectangle of words. Areas, intersections and unions
//! are word-wise AND + popcount, restricted to bounding boxes where that helps.

use serde::{Deserialize, Serialize};

/// Why a mask could not be built or compared.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MaskError {
    #[error("{what} has {found} values but a {width}x{height} mask needs {expected}")]
    LengthMismatch {
        what: &'static str,
        width: u32,
        height: u32,
        expected: usize,
        found: usize,
    },
    #[error("masks differ in size: {first_width}x{first_height} vs {second_width}x{second_height}")]
    SizeMismatch {
        first_width: u32,
        first_height: u32,
        second_width: u32,
        second_height: u32,
    },
}

/// Pixel bounds of a non-empty mask, all four inclusive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct BoundingBox {
    pub x_min: u32,
    pub y_min: u32,
    pub x_max: u32,
    pub y_max: u32,
}

impl BoundingBox {
    pub fn width(&self) -> u32 {
        self.x_max - self.x_min + 1
    }

    pub fn height(&self) -> u32 {
        self.y_max - self.y_min + 1
    }

    /// Pixels inside the box (inclusive bounds, so a one-pixel box has area 1).
    pub fn area(&self) -> u64 {
        u64::from(self.width()) * u64::from(self.height())
    }

    /// The overlap of two boxes, `None` when they share no pixel.
    pub fn intersection(&self, other: &BoundingBox) -> Option<BoundingBox> {
        let overlap = BoundingBox {
            x_min: self.x_min.max(other.x_min),
            y_min: self.y_min.max(other.y_min),
            x_max: self.x_max.min(other.x_max),
            y_max: self.y_max.min(other.y_max),
        };
        (overlap.x_min <= overlap.x_max && overlap.y_min <= overlap.y_max).then_some(overlap)
    }

    /// Box IoU over pixel counts (inclusive bounds; SAM's torchvision NMS uses `x_max - x_min`,
    /// one pixel less per side, which only matters for boxes a few pixels wide).
    pub fn iou(&self, other: &BoundingBox) -> f32 {
        let Some(overlap) = self.intersection(other) else {
            return 0.0;
        };
        let intersection = overlap.area() as f64;
        let union = self.area() as f64 + other.area() as f64 - intersection;
        (intersection / union) as f32
    }

    /// The box grown by `margin` pixels on every side, clamped to a `width x height` image.
    pub fn expanded(&self, margin: u32, width: u32, height: u32) -> BoundingBox {
        BoundingBox {
            x_min: self.x_min.saturating_sub(margin),
            y_min: self.y_min.saturating_sub(margin),
            x_max: (self.x_max + margin).min(width.saturating_sub(1)),
            y_max: (self.y_max + margin).min(height.saturating_sub(1)),
        }
    }

    /// COCO's `[x, y, width, height]`.
    pub fn to_xywh(&self) -> [u32; 4] {
        [self.x_min, self.y_min, self.width(), self.height()]
    }
}

/// A `width x height` binary mask. Bits past `width` in each row's last word are always zero.
#[derive(Clone, PartialEq, Eq)]
pub struct BitMask {
    width: u32,
    height: u32,
    words_per_row: usize,
    words: Vec<u64>,
}

impl std::fmt::Debug for BitMask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BitMask")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("area", &self.area())
            .field("bounding_box", &self.bounding_box())
            .finish()
    }
}

impl BitMask {
    /// An empty mask.
    pub fn new(width: u32, height: u32) -> Self {
        let words_per_row = (width as usize).div_ceil(64);
        BitMask {
            width,
            height,
            words_per_row,
            words: vec![0; words_per_row * height as usize],
        }
    }

    /// Pixels where `predicate(index)` holds, `index` running row-major over `width x height`.
    fn from_predicate(width: u32, height: u32, mut predicate: impl FnMut(usize) -> bool) -> Self {
        let mut mask = BitMask::new(width, height);
        let row_len = width as usize;
        for y in 0..height as usize {
            let row_words = &mut mask.words[y * mask.words_per_row..(y + 1) * mask.words_per_row];
            for (word_index, word) in row_words.iter_mut().enumerate() {
                let x_start = word_index * 64;
                let x_end = (x_start + 64).min(row_len);
                let mut bits = 0u64;
                for x in x_start..x_end {
                    if predicate(y * row_len + x) {
                        bits |= 1 << (x - x_start);
                    }
                }
                *word = bits;
            }
        }
        mask
    }

    fn check_length(
        what: &'static str,
        width: u32,
        height: u32,
        found: usize,
    ) -> Result<(), MaskError> {
        let expected = width as usize * height as usize;
        if found != expected {
            return Err(MaskError::LengthMismatch {
                what,
                width,
                height,
                expected,
                found,
            });
        }
        Ok(())
    }

    /// Pixels whose logit is strictly above `threshold` (SAM: logits > 0 are the mask).
    pub fn from_logits(
        width: u32,
        height: u32,
        logits: &[f32],
        threshold: f32,
    ) -> Result<Self, MaskError> {
        Self::check_length("logits", width, height, logits.len())?;
        Ok(Self::from_predicate(width, height, |index| {
            logits[index] > threshold
        }))
    }

    /// Pixels where `values` is true, row-major.
    pub fn from_bools(width: u32, height: u32, values: &[bool]) -> Result<Self, MaskError> {
        Self::check_length("values", width, height, values.len())?;
        Ok(Self::from_predicate(width, height, |index| values[index]))
    }

    /// Pixels of an instance-id image (row-major) that carry `id`.
    pub fn from_instance_id(
        width: u32,
        height: u32,
        ids: &[u32],
        id: u32,
    ) -> Result<Self, MaskError> {
        Self::check_length("instance ids", width, height, ids.len())?;
        Ok(Self::from_predicate(width, height, |index| {
            ids[index] == id
        }))
    }

    /// One mask per distinct non-zero id of an instance-id image, in increasing id order, built in
    /// a single pass over the pixels.
    pub fn all_from_instance_ids(
        width: u32,
        height: u32,
        ids: &[u32],
    ) -> Result<Vec<(u32, BitMask)>, MaskError> {
        Self::check_length("instance ids", width, height, ids.len())?;
        let mut mask_index_from_id = std::collections::BTreeMap::<u32, usize>::new();
        let mut masks: Vec<BitMask> = Vec::new();
        for (index, &id) in ids.iter().enumerate() {
            if id == 0 {
                continue;
            }
            let mask_index = *mask_index_from_id.entry(id).or_insert_with(|| {
                masks.push(BitMask::new(width, height));
                masks.len() - 1
            });
            let (x, y) = (index % width as usize, index / width as usize);
            masks[mask_index].set(x as u32, y as u32, true);
        }
        let mut slots: Vec<Option<BitMask>> = masks.into_iter().map(Some).collect();
        Ok(mask_index_from_id
            .into_iter()
            .filter_map(|(id, mask_index)| slots[mask_index].take().map(|mask| (id, mask)))
            .collect())
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Whether pixel `(x, y)` is set; pixels outside the image are not.
    pub fn get(&self, x: u32, y: u32) -> bool {
        if x >= self.width || y >= self.height {
            return false;
        }
        let word = self.words[y as usize * self.words_per_row + x as usize / 64];
        (word >> (x % 64)) & 1 == 1
    }

    /// Sets or clears pixel `(x, y)`; pixels outside the image are ignored.
    pub fn set(&mut self, x: u32, y: u32, value: bool) {
        if x >= self.width || y >= self.height {
            return;
        }
        let word = &mut self.words[y as usize * self.words_per_row + x as usize / 64];
        let bit = 1u64 << (x % 64);
        if value {
            *word |= bit;
        } else {
            *word &= !bit;
        }
    }

    /// Sets or clears pixels `x_range` of row `y` a word at a time (clipped to the image), for
    /// rasterising shapes.
    pub fn set_row_span(&mut self, y: u32, x_range: std::ops::Range<u32>, value: bool) {
        let x_end = x_range.end.min(self.width);
        if y >= self.height || x_range.start >= x_end {
            return;
        }
        let row_start = y as usize * self.words_per_row;
        let (first, last) = (x_range.start as usize, x_end as usize - 1);
        for word_index in first / 64..=last / 64 {
            let low = first.max(word_index * 64) - word_index * 64;
            let high = last.min(word_index * 64 + 63) - word_index * 64;
            let bits = (u64::MAX >> (63 - high)) & (u64::MAX << low);
            let word = &mut self.words[row_start + word_index];
            if value {
                *word |= bits;
            } else {
                *word &= !bits;
            }
        }
    }

    /// Set pixels (popcount).
    pub fn area(&self) -> u64 {
        self.words
            .iter()
            .map(|word| u64::from(word.count_ones()))
            .sum()
    }

    pub fn is_empty(&self) -> bool {
        self.words.iter().all(|&word| word == 0)
    }

    /// The tightest box around the set pixels; `None` for an empty mask.
    pub fn bounding_box(&self) -> Option<BoundingBox> {
        if self.words_per_row == 0 {
            return None;
        }
        let mut rows = self.words.chunks_exact(self.words_per_row);
        let y_min = rows.position(|row| row.iter().any(|&word| word != 0))?;
        let y_max = self
            .words
            .chunks_exact(self.words_per_row)
            .rposition(|row| row.iter().any(|&word| word != 0))?;
        // Column extent: OR all rows in range, then find the first and last set bit.
        let mut columns = vec![0u64; self.words_per_row];
        for row in self.words[y_min * self.words_per_row..(y_max + 1) * self.words_per_row]
            .chunks_exact(self.words_per_row)
        {
            for (accumulated, &word) in columns.iter_mut().zip(row) {
                *accumulated |= word;
            }
        }
        let first_word = columns.iter().position(|&word| word != 0)?;
        let last_word = columns.iter().rposition(|&word| word != 0)?;
        let x_min = first_word * 64 + columns[first_word].trailing_zeros() as usize;
        let x_max = last_word * 64 + 63 - columns[last_word].leading_zeros() as usize;
        Some(BoundingBox {
            x_min: x_min as u32,
            y_min: y_min as u32,
            x_max: x_max as u32,
            y_max: y_max as u32,
        })
    }

    fn check_same_size(&self, other: &BitMask) -> Result<(), MaskError> {
        if (self.width, self.height) != (other.width, other.height) {
            return Err(MaskError::SizeMismatch {
                first_width: self.width,
                first_height: self.height,
                second_width: other.width,
                second_height: other.height,
            });
        }
        Ok(())
    }

    /// Pixels set in both masks.
    pub fn intersection_area(&self, other: &BitMask) -> Result<u64, MaskError> {
        self.check_same_size(other)?;
        Ok(self
            .words
            .iter()
            .zip(&other.words)
            .map(|(a, b)| u64::from((a & b).count_ones()))
            .sum())
    }

    /// Pixels set in either mask.
    pub fn union_area(&self, other: &BitMask) -> Result<u64, MaskError> {
        self.check_same_size(other)?;
        Ok(self
            .words
            .iter()
            .zip(&other.words)
            .map(|(a, b)| u64::from((a | b).count_ones()))
            .sum())
    }

    /// Intersection over union; 0 when both are empty.
    pub fn iou(&self, other: &BitMask) -> Result<f32, MaskError> {
        let intersection = self.intersection_area(other)?;
        let union = self.area() + other.area() - intersection;
        Ok(if union == 0 {
            0.0
        } else {
            (intersection as f64 / union as f64) as f32
        })
    }

    /// Pixels set in both masks, counting only words that cover `overlap`. Exact when `overlap`
    /// contains the intersection of the two masks' bounding boxes (outside it one mask is zero),
    /// which is how mask NMS calls it. The caller guarantees equal sizes.
    pub(crate) fn intersection_area_within(&self, other: &BitMask, overlap: &BoundingBox) -> u64 {
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        let first_word = overlap.x_min as usize / 64;
        let last_word = overlap.x_max as usize / 64;
        let mut total = 0u64;
        for y in overlap.y_min as usize..=overlap.y_max as usize {
            let row_start = y * self.words_per_row;
            let a = &self.words[row_start + first_word..=row_start + last_word];
            let b = &other.words[row_start + first_word..=row_start + last_word];
            total += a
                .iter()
                .zip(b)
                .map(|(a, b)| u64::from((a & b).count_ones()))
                .sum::<u64>();
        }
        total
    }

    /// Sets every pixel that is set in `other` (same size).
    pub fn union_with(&mut self, other: &BitMask) -> Result<(), MaskError> {
        self.check_same_size(other)?;
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a |= b;
        }
        Ok(())
    }

    /// One bool per pixel, row-major.
    pub fn to_bools(&self) -> Vec<bool> {
        let mut values = Vec::with_capacity(self.width as usize * self.height as usize);
        for y in 0..self.height {
            for x in 0..self.width {
                values.push(self.get(x, y));
            }
        }
        values
    }

    /// Iterates the set pixels of one row as `x` coordinates, in increasing order.
    pub fn row_set_columns(&self, y: u32) -> impl Iterator<Item = u32> + '_ {
        let row_start = y as usize * self.words_per_row;
        self.words[row_start..row_start + self.words_per_row]
            .iter()
            .enumerate()
            .flat_map(|(word_index, &word)| {
                let mut remaining = word;
                std::iter::from_fn(move || {
                    if remaining == 0 {
                        return None;
                    }
                    let bit = remaining.trailing_zeros();
                    remaining &= remaining - 1;
                    Some(word_index as u32 * 64 + bit)
                })
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rectangle(width: u32, height: u32, bounds: BoundingBox) -> BitMask {
        let mut mask = BitMask::new(width, height);
        for y in bounds.y_min..=bounds.y_max {
            for x in bounds.x_min..=bounds.x_max {
                mask.set(x, y, true);
            }
        }
        mask
    }

    #[test]
    fn area_and_bounding_box_span_word_boundaries() {
        let bounds = BoundingBox {
            x_min: 60,
            y_min: 3,
            x_max: 130,
            y_max: 9,
        };
        let mask = rectangle(200, 12, bounds);
        assert_eq!(mask.area(), 71 * 7);
        assert_eq!(mask.bounding_box(), Some(bounds));
        assert!(mask.get(60, 3) && mask.get(130, 9));
        assert!(!mask.get(59, 3) && !mask.get(131, 9) && !mask.get(500, 3));
        assert_eq!(BitMask::new(200, 12).bounding_box(), None);
    }

    #[test]
    fn intersection_and_union_match_per_pixel_counts() {
        let a = rectangle(
            150,
            40,
            BoundingBox {
                x_min: 10,
                y_min: 5,
                x_max: 100,
                y_max: 30,
            },
        );
        let b = rectangle(
            150,
            40,
            BoundingBox {
                x_min: 50,
                y_min: 20,
                x_max: 149,
                y_max: 39,
            },
        );
        let per_pixel_intersection = a
            .to_bools()
            .iter()
            .zip(b.to_bools())
            .filter(|(a, b)| **a && *b)
            .count() as u64;
        assert_eq!(per_pixel_intersection, 51 * 11);
        assert_eq!(a.intersection_area(&b), Ok(per_pixel_intersection));
        assert_eq!(
            a.union_area(&b),
            Ok(a.area() + b.area() - per_pixel_intersection)
        );
        let overlap = a.bounding_box().and_then(|box_a| {
            b.bounding_box()
                .and_then(|box_b| box_a.intersection(&box_b))
        });
        let overlap = overlap.expect("boxes overlap");
        assert_eq!(
            a.intersection_area_within(&b, &overlap),
            per_pixel_intersection
        );
        let iou = a.iou(&b).expect("same size");
        let expected =
            per_pixel_intersection as f32 / (a.area() + b.area() - per_pixel_intersection) as f32;
        assert!((iou - expected).abs() < 1e-6);
    }

    #[test]
    fn logits_threshold_is_strict_and_lengths_are_checked() {
        let logits = [0.0, 0.5, -1.0, 2.0, 0.0, 1e-3];
        let mask = BitMask::from_logits(3, 2, &logits, 0.0).expect("length fits");
        assert_eq!(mask.to_bools(), vec![false, true, false, true, false, true]);
        assert!(matches!(
            BitMask::from_logits(4, 2, &logits, 0.0),
            Err(MaskError::LengthMismatch {
                expected: 8,
                found: 6,
                ..
            })
        ));
        assert!(
            BitMask::new(3, 2)
                .intersection_area(&BitMask::new(2, 3))
                .is_err()
        );
    }

    #[test]
    fn instance_ids_split_into_one_mask_per_id() {
        let ids = [0, 7, 7, 2, 0, 2];
        let masks = BitMask::all_from_instance_ids(3, 2, &ids).expect("length fits");
        assert_eq!(masks.len(), 2);
        assert_eq!(masks[0].0, 2);
        assert_eq!(
            masks[0].1.to_bools(),
            vec![false, false, false, true, false, true]
        );
        assert_eq!(masks[1].0, 7);
        assert_eq!(
            masks[1].1,
            BitMask::from_instance_id(3, 2, &ids, 7).expect("length fits")
        );
    }

    #[test]
    fn row_spans_match_pixel_by_pixel_setting() {
        let mut by_span = BitMask::new(150, 3);
        let mut by_pixel = BitMask::new(150, 3);
        for (y, start, end) in [(0, 3, 64), (1, 60, 140), (2, 0, 500), (1, 10, 10)] {
            by_span.set_row_span(y, start..end, true);
            for x in start..end.min(150) {
                by_pixel.set(x, y, true);
            }
        }
        by_span.set_row_span(1, 63..129, false);
        for x in 63..129 {
            by_pixel.set(x, 1, false);
        }
        assert_eq!(by_span, by_pixel);
        assert_eq!(by_span.area(), by_pixel.area());
    }

    #[test]
    fn row_columns_lists_set_pixels() {
        let mut mask = BitMask::new(130, 2);
        for x in [0, 63, 64, 129] {
            mask.set(x, 1, true);
        }
        assert_eq!(
            mask.row_set_columns(1).collect::<Vec<_>>(),
            vec![0, 63, 64, 129]
        );
        assert_eq!(mask.row_set_columns(0).count(), 0);
    }
}
