//! New objects (docs/method.md stage 1 step 3): when a level's uncovered share grew since the last
//! look, new-object masks are generated on the frame and the candidates that mostly cover
//! uncovered pixels become objects.

use crate::segment::{BitMask, ScoredMask};

/// The per-level thresholds the uncovered share is compared with.
///
/// A threshold follows the share down as coverage improves, and after a look it is reset to the
/// share left once the new objects were added. Growth is thus measured from the best coverage
/// since the last look: an object leaving the frame (its pixels now uncovered, nothing there to
/// find) causes one look, not one at every later check.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Ratchet {
    thresholds: [f64; 3],
}

impl Ratchet {
    pub fn new(uncovered: [f64; 3]) -> Ratchet {
        Ratchet {
            thresholds: uncovered,
        }
    }

    pub fn thresholds(&self) -> [f64; 3] {
        self.thresholds
    }

    /// Whether any level's uncovered share grew by more than `growth` over its threshold.
    pub fn grew(&self, uncovered: [f64; 3], growth: f64) -> bool {
        uncovered
            .iter()
            .zip(&self.thresholds)
            .any(|(share, threshold)| *share > threshold + growth)
    }

    /// After a check: `uncovered` is the share once any new objects were added.
    pub fn settle(&mut self, uncovered: [f64; 3], looked: bool) {
        for (threshold, share) in self.thresholds.iter_mut().zip(uncovered) {
            *threshold = if looked { share } else { threshold.min(share) };
        }
    }
}

/// The candidates of one level that are new objects: more than `min_area` pixels, of which more
/// than `min_uncovered_share` are neither in `ids` (the level's objects, 0 = none) nor in a
/// candidate taken before (candidates come best first). Masks must be the size of `ids`.
pub(super) fn new_object_masks<'a>(
    candidates: &'a [ScoredMask],
    ids: &[u32],
    min_area: f64,
    min_uncovered_share: f64,
) -> Vec<&'a ScoredMask> {
    let Some(first) = candidates.first() else {
        return Vec::new();
    };
    let width = first.mask.width() as usize;
    let mut taken = BitMask::new(first.mask.width(), first.mask.height());
    let mut new = Vec::new();
    for candidate in candidates {
        if candidate.area as f64 <= min_area {
            continue;
        }
        let mut uncovered = 0u64;
        for y in candidate.bbox.y_min..=candidate.bbox.y_max {
            let row = y as usize * width;
            uncovered += candidate
                .mask
                .row_set_columns(y)
                .filter(|&x| ids[row + x as usize] == 0 && !taken.get(x, y))
                .count() as u64;
        }
        if uncovered as f64 > min_uncovered_share * candidate.area as f64
            && taken.union_with(&candidate.mask).is_ok()
        {
            new.push(candidate);
        }
    }
    new
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(x0: u32, width: u32) -> ScoredMask {
        let mut mask = BitMask::new(20, 4);
        for y in 0..4 {
            mask.set_row_span(y, x0..x0 + width, true);
        }
        ScoredMask::certain(mask, None).expect("non-empty")
    }

    #[test]
    fn the_ratchet_looks_once_per_growth() {
        let mut ratchet = Ratchet::new([0.3, 0.5, 0.1]);
        assert!(!ratchet.grew([0.305, 0.4, 0.1], 0.01));
        ratchet.settle([0.305, 0.4, 0.1], false);
        assert_eq!(ratchet.thresholds(), [0.3, 0.4, 0.1]);
        assert!(ratchet.grew([0.3, 0.42, 0.1], 0.01));
        ratchet.settle([0.3, 0.42, 0.1], true);
        assert!(!ratchet.grew([0.3, 0.42, 0.1], 0.01), "nothing new since");
    }

    #[test]
    fn candidates_must_be_large_and_mostly_uncovered() {
        // Pixels 0..8 of each row are covered.
        let ids: Vec<u32> = (0..80).map(|i| u32::from(i % 20 < 8)).collect();
        let candidates = [
            candidate(4, 6),  // 4 of 6 columns covered: not new
            candidate(6, 8),  // 6 of 8 uncovered: new
            candidate(10, 6), // overlaps the one just taken on 4 of 6: not new
            candidate(16, 4), // new, but 16 pixels only
            candidate(18, 2), // too small
        ];
        let new = new_object_masks(&candidates, &ids, 12.0, 0.5);
        assert_eq!(new.len(), 2);
        assert_eq!(new[0].bbox.x_min, 6);
        assert_eq!(new[1].bbox.x_min, 16);
        assert!(new_object_masks(&candidates, &ids, 16.0, 0.5).len() == 1);
    }
}
