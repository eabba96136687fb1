//! Duplicate tracks (docs/method.md stage 1 step 4): two tracks of one level that follow the same
//! object. Their whole masks (before overlaps were resolved, which would hide the overlap) are
//! compared at every check frame where both were answered; the IoU pooled over those frames
//! (summed intersections over summed unions) decides, so one bad frame neither makes nor breaks
//! a pair. The smaller track (fewer pixels over the same frames) is dropped, ties the newer.
//!
//! Dropping is global: in every frame the dropped id's pixels go to the kept id where that frame
//! shows the kept object (the two are one object there, and the overlap rule may have handed the
//! shared pixels to the dropped one), and to no object elsewhere.

use std::collections::{HashMap, HashSet};

use super::track::Track;

#[derive(Debug, Clone, Copy, Default)]
struct Pooled {
    intersection: u64,
    union: u64,
    /// Summed areas of the lower and the higher id, over the same frames.
    area_low: u64,
    area_high: u64,
}

impl Pooled {
    fn iou(&self) -> f64 {
        if self.union == 0 {
            0.0
        } else {
            self.intersection as f64 / self.union as f64
        }
    }
}

/// A drop decided at a check: `(dropped, kept, pooled IoU)`.
pub(super) type Drop = (u32, u32, f64);

/// The pooled pair counts of every level, and the drops so far.
#[derive(Debug, Default)]
pub(super) struct DuplicateLedger {
    /// `(level, lower id, higher id)`: only pairs that ever overlapped.
    pairs: HashMap<(usize, u32, u32), Pooled>,
    /// `(level, dropped id)` to the id kept in its place.
    kept_for: HashMap<(usize, u32), u32>,
}

impl DuplicateLedger {
    /// Adds one check frame's masks of the tracks answered in it (`tracks` of any levels) and
    /// returns the pairs now above `threshold` as drops, most overlapping first. A track is
    /// dropped at most once per call and never in favour of one dropped in the same call.
    pub fn sample(&mut self, tracks: &[&Track], threshold: f64) -> Vec<(usize, Drop)> {
        let seen: Vec<&Track> = tracks.iter().copied().filter(|t| t.is_seen()).collect();
        for (index, a) in seen.iter().enumerate() {
            for b in &seen[index + 1..] {
                if a.level != b.level {
                    continue;
                }
                let (low, high) = if a.id < b.id { (a, b) } else { (b, a) };
                let key = (a.level, low.id, high.id);
                let overlap = low.bbox.intersection(&high.bbox);
                if overlap.is_none() && !self.pairs.contains_key(&key) {
                    continue;
                }
                let intersection = overlap.map_or(0, |overlap| {
                    low.mask.intersection_area_within(&high.mask, &overlap)
                });
                let pooled = self.pairs.entry(key).or_default();
                pooled.intersection += intersection;
                pooled.union += low.area + high.area - intersection;
                pooled.area_low += low.area;
                pooled.area_high += high.area;
            }
        }
        let present: HashSet<(usize, u32)> = seen.iter().map(|t| (t.level, t.id)).collect();
        let mut above: Vec<((usize, u32, u32), Pooled)> = self
            .pairs
            .iter()
            .filter(|((level, low, high), pooled)| {
                present.contains(&(*level, *low))
                    && present.contains(&(*level, *high))
                    && pooled.iou() > threshold
            })
            .map(|(key, pooled)| (*key, *pooled))
            .collect();
        above.sort_by(|a, b| b.1.iou().total_cmp(&a.1.iou()).then(a.0.cmp(&b.0)));
        let mut touched = HashSet::new();
        let mut drops = Vec::new();
        for ((level, low, high), pooled) in above {
            if touched.contains(&(level, low)) || touched.contains(&(level, high)) {
                continue;
            }
            let (dropped, kept) = if pooled.area_high <= pooled.area_low {
                (high, low)
            } else {
                (low, high)
            };
            touched.insert((level, low));
            touched.insert((level, high));
            self.kept_for.insert((level, dropped), kept);
            drops.push((level, (dropped, kept, pooled.iou())));
        }
        drops
    }

    /// The id finally kept for `id` at `level` (following drops of kept ids), `None` when `id`
    /// was never dropped.
    fn survivor(&self, level: usize, id: u32) -> Option<u32> {
        let mut current = *self.kept_for.get(&(level, id))?;
        // Each drop points at an id that was live when it was dropped, so chains end; the bound
        // only guards against a malformed ledger.
        for _ in 0..=self.kept_for.len() {
            match self.kept_for.get(&(level, current)) {
                Some(&next) => current = next,
                None => break,
            }
        }
        Some(current)
    }

    /// Rewrites every frame's ids for the drops (see the module documentation).
    pub fn apply(&self, frames: &mut [[Vec<u32>; 3]]) {
        if self.kept_for.is_empty() {
            return;
        }
        for frame in frames.iter_mut() {
            for (level, ids) in frame.iter_mut().enumerate() {
                let present: HashSet<u32> = ids.iter().copied().collect();
                let mut replacement: HashMap<u32, u32> = HashMap::new();
                for &id in &present {
                    if let Some(kept) = self.survivor(level, id) {
                        replacement.insert(id, if present.contains(&kept) { kept } else { 0 });
                    }
                }
                if replacement.is_empty() {
                    continue;
                }
                for id in ids.iter_mut() {
                    if let Some(&new) = replacement.get(id) {
                        *id = new;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment::BitMask;

    fn track(id: u32, level: usize, x0: u32, width: u32) -> Track {
        let mut mask = BitMask::new(20, 2);
        for y in 0..2 {
            mask.set_row_span(y, x0..x0 + width, true);
        }
        Track::new(id, level, mask, 0.9).expect("non-empty")
    }

    #[test]
    fn pooled_overlap_drops_the_smaller_track_once() {
        let mut ledger = DuplicateLedger::default();
        let (a, b, c) = (track(1, 0, 0, 10), track(2, 0, 0, 10), track(3, 0, 12, 4));
        // Same place at another level: no pair.
        let other_level = track(4, 1, 0, 10);
        // First check: 2 covers half of 1.
        let half = track(2, 0, 0, 5);
        assert!(
            ledger
                .sample(&[&a, &half, &c, &other_level], 0.5)
                .is_empty()
        );
        // Second: identical; pooled (10 + 20) / (20 + 20) = 0.75.
        let drops = ledger.sample(&[&a, &b, &c, &other_level], 0.5);
        assert_eq!(drops, vec![(0, (2, 1, 0.75))]);

        let mut frames = vec![[vec![2, 2, 1, 0], vec![4, 0, 0, 0], vec![0; 4]]];
        frames.push([vec![2, 2, 0, 3], vec![4; 4], vec![0; 4]]);
        ledger.apply(&mut frames);
        assert_eq!(
            frames[0][0],
            vec![1, 1, 1, 0],
            "to the kept track where it shows"
        );
        assert_eq!(
            frames[1][0],
            vec![0, 0, 0, 3],
            "to nothing where it does not"
        );
        assert_eq!(frames[1][1], vec![4; 4], "other levels untouched");
    }

    #[test]
    fn chains_of_drops_end_at_the_survivor() {
        let mut ledger = DuplicateLedger::default();
        ledger.kept_for.insert((0, 5), 3);
        ledger.kept_for.insert((0, 3), 1);
        assert_eq!(ledger.survivor(0, 5), Some(1));
        assert_eq!(ledger.survivor(0, 1), None);
        let mut frames = vec![[vec![5, 1], vec![5, 0], vec![0, 0]]];
        ledger.apply(&mut frames);
        assert_eq!(frames[0][0], vec![1, 1]);
        assert_eq!(frames[0][1], vec![5, 0], "level 1 has no drops");
    }
}
