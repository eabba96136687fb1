//! Runs of equal ids in an instance-id map (row-major, 0 = no object). Masks are regions, so a
//! row crosses few of them: at 1000 px a figurine view's 658k pixels make a few thousand runs
//! per level. Counting, listing and rewriting ids run by run instead of pixel by pixel is what
//! keeps the segment stage's per-pixel map lookups and full-map sorts off its serial path (issue
//! 38, item 5).

use std::ops::Range;

/// The maximal runs of equal ids, in pixel order: each run's id and its pixels.
pub fn id_runs(ids: &[u32]) -> impl Iterator<Item = (u32, Range<usize>)> + '_ {
    let mut start = 0;
    ids.chunk_by(|a, b| a == b).map(move |run| {
        let pixels = start..start + run.len();
        start = pixels.end;
        (run[0], pixels)
    })
}

/// Every object of an id map (0 left out), ascending, with its pixel count.
pub fn id_pixel_counts(ids: &[u32]) -> Vec<(u32, usize)> {
    let mut runs: Vec<(u32, usize)> = id_runs(ids)
        .filter(|(id, _)| *id != 0)
        .map(|(id, pixels)| (id, pixels.len()))
        .collect();
    runs.sort_unstable_by_key(|&(id, _)| id);
    let mut counts: Vec<(u32, usize)> = Vec::new();
    for (id, pixels) in runs {
        match counts.last_mut() {
            Some((last, count)) if *last == id => *count += pixels,
            _ => counts.push((id, pixels)),
        }
    }
    counts
}

/// The smallest pixel rectangle holding every pixel of one id: columns `x_min..=x_max`, rows
/// `y_min..=y_max`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelBounds {
    pub x_min: u32,
    pub y_min: u32,
    pub x_max: u32,
    pub y_max: u32,
}

impl PixelBounds {
    fn join(self, other: Self) -> Self {
        Self {
            x_min: self.x_min.min(other.x_min),
            y_min: self.y_min.min(other.y_min),
            x_max: self.x_max.max(other.x_max),
            y_max: self.y_max.max(other.y_max),
        }
    }

    /// Whether any pixel of the rectangle lies in columns `x..=x + 1` and rows `y..=y + 1`.
    pub fn touches_square(&self, x: i64, y: i64) -> bool {
        x + 1 >= i64::from(self.x_min)
            && x <= i64::from(self.x_max)
            && y + 1 >= i64::from(self.y_min)
            && y <= i64::from(self.y_max)
    }
}

/// Every object of an id map `width` pixels wide (0 left out), ascending, with its bounds.
pub fn id_bounds(ids: &[u32], width: usize) -> Vec<(u32, PixelBounds)> {
    let width = width.max(1);
    let mut runs: Vec<(u32, PixelBounds)> = id_runs(ids)
        .filter(|(id, _)| *id != 0)
        .map(|(id, pixels)| {
            let (first, last) = (pixels.start, pixels.end - 1);
            let (y_min, y_max) = (first / width, last / width);
            // A run that wraps onto the next row holds the last column and the first.
            let (x_min, x_max) = if y_min == y_max {
                (first % width, last % width)
            } else {
                (0, width - 1)
            };
            let bounds = PixelBounds {
                x_min: x_min as u32,
                y_min: y_min as u32,
                x_max: x_max as u32,
                y_max: y_max as u32,
            };
            (id, bounds)
        })
        .collect();
    runs.sort_unstable_by_key(|&(id, _)| id);
    let mut joined: Vec<(u32, PixelBounds)> = Vec::new();
    for (id, bounds) in runs {
        match joined.last_mut() {
            Some((last, so_far)) if *last == id => *so_far = so_far.join(bounds),
            _ => joined.push((id, bounds)),
        }
    }
    joined
}

/// Replaces every id `replacement` maps to something, run by run.
pub fn replace_ids(ids: &mut [u32], mut replacement: impl FnMut(u32) -> Option<u32>) {
    for run in ids.chunk_by_mut(|a, b| a == b) {
        if let Some(new_id) = replacement(run[0]) {
            run.fill(new_id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn random_ids(seed: u64, pixels: usize, ids: u32) -> Vec<u32> {
        // Regions of random lengths, as a mask's rows cross them, with id 0 among them.
        let mut state = seed;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 33) as u32
        };
        let mut map = Vec::with_capacity(pixels);
        while map.len() < pixels {
            let (id, length) = (next() % ids, 1 + next() as usize % 40);
            map.extend(std::iter::repeat_n(id, length.min(pixels - map.len())));
        }
        map
    }

    #[test]
    fn runs_cover_the_map_in_order_and_are_maximal() {
        let ids = random_ids(3, 5000, 6);
        let runs: Vec<(u32, Range<usize>)> = id_runs(&ids).collect();
        let mut expected_start = 0;
        for (index, (id, pixels)) in runs.iter().enumerate() {
            assert_eq!(pixels.start, expected_start);
            assert!(!pixels.is_empty());
            assert!(ids[pixels.clone()].iter().all(|pixel| pixel == id));
            if let Some((next_id, _)) = runs.get(index + 1) {
                assert_ne!(next_id, id, "runs of one id must be joined");
            }
            expected_start = pixels.end;
        }
        assert_eq!(expected_start, ids.len());
        assert_eq!(id_runs(&[]).count(), 0);
    }

    #[test]
    fn pixel_counts_equal_counting_each_pixel() {
        for seed in 0..8 {
            let ids = random_ids(seed, 10_000, 50);
            let mut expected: BTreeMap<u32, usize> = BTreeMap::new();
            for &id in ids.iter().filter(|&&id| id != 0) {
                *expected.entry(id).or_default() += 1;
            }
            let expected: Vec<(u32, usize)> = expected.into_iter().collect();
            assert_eq!(id_pixel_counts(&ids), expected);
        }
        assert!(id_pixel_counts(&[0, 0, 0]).is_empty());
    }

    #[test]
    fn bounds_are_the_pixels_tightest_rectangle() {
        for (seed, width) in [(1, 37), (2, 100), (4, 1)] {
            let ids = random_ids(seed, 3700, 30);
            let mut expected: BTreeMap<u32, PixelBounds> = BTreeMap::new();
            for (pixel, &id) in ids.iter().enumerate().filter(|(_, id)| **id != 0) {
                let (x, y) = ((pixel % width) as u32, (pixel / width) as u32);
                let here = PixelBounds {
                    x_min: x,
                    y_min: y,
                    x_max: x,
                    y_max: y,
                };
                expected
                    .entry(id)
                    .and_modify(|bounds| *bounds = bounds.join(here))
                    .or_insert(here);
            }
            let expected: Vec<(u32, PixelBounds)> = expected.into_iter().collect();
            assert_eq!(id_bounds(&ids, width), expected, "width {width}");
        }
        let bounds = PixelBounds {
            x_min: 4,
            y_min: 2,
            x_max: 6,
            y_max: 2,
        };
        assert!(bounds.touches_square(3, 1) && bounds.touches_square(6, 2));
        assert!(!bounds.touches_square(2, 2) && !bounds.touches_square(7, 2));
        assert!(!bounds.touches_square(4, 0) && !bounds.touches_square(4, 3));
    }

    #[test]
    fn replacing_by_runs_equals_replacing_each_pixel() {
        let ids = random_ids(5, 10_000, 20);
        let replacement = |id: u32| (id % 3 == 1).then_some(id / 2);
        let expected: Vec<u32> = ids
            .iter()
            .map(|&id| replacement(id).unwrap_or(id))
            .collect();
        let mut replaced = ids.clone();
        replace_ids(&mut replaced, replacement);
        assert_eq!(replaced, expected);
    }
}
