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
