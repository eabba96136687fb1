//! What the partial-mask filter found, in figures an operator can read: how many (object, view)
//! pairs it checked and left out per level, how their IoUs spread, and how many of the left-out
//! pairs are objects that render nothing at all in that view. The last is the figure that tells
//! a filter cutting "partial" masks from one that meets objects the model never gave Gaussians
//! (on the figurine with classical masks, most of what it leaves out: docs/benchmarks.md).

use serde::{Deserialize, Serialize};

use crate::train::SkippedPair;

/// The overlap of one pair: pixels where the object's render alone covers (alpha > 0.5) and its
/// mask holds it, and where either does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PairOverlap {
    pub intersection: u32,
    pub union: u32,
}

impl PairOverlap {
    /// IoU; a pair whose render and mask are both empty scores 0.
    pub fn iou(self) -> f32 {
        if self.union == 0 {
            0.0
        } else {
            self.intersection as f32 / self.union as f32
        }
    }

    /// Pixels the object's render covers (alpha > 0.5) in the view, given its mask's pixels.
    pub fn rendered_pixels(self, mask_pixels: u32) -> u32 {
        (self.union + self.intersection).saturating_sub(mask_pixels)
    }
}

/// The filter's findings (`metrics.json` `partial_filter` of a Segment-then-Splat job).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartialFilterReport {
    /// The step after which the filter ran.
    pub after_step: u32,
    /// The IoU below which a pair is left out.
    pub iou_threshold: f32,
    /// Pairs checked, per level (small, middle, large).
    pub pairs: [usize; 3],
    /// Pairs left out, per level.
    pub skipped: [usize; 3],
    /// Left-out pairs whose object covers no pixel of the view: no Gaussians of its own (or
    /// none left there). The object loss can never fit these masks; they are not partial views.
    pub skipped_rendering_nothing: usize,
    /// The pairs' IoUs at 25%, 50% and 75% (nearest rank).
    pub iou_quartiles: [f32; 3],
}

impl PartialFilterReport {
    /// Judges every pair (`pairs[i]`, its mask's pixels `mask_pixels[i]`, `overlaps[i]`) against
    /// `threshold` and returns the left-out pairs with the report.
    pub fn judge(
        after_step: u32,
        threshold: f32,
        pairs: &[SkippedPair],
        mask_pixels: &[u32],
        overlaps: &[PairOverlap],
    ) -> (Vec<SkippedPair>, Self) {
        let mut report = Self {
            after_step,
            iou_threshold: threshold,
            pairs: [0; 3],
            skipped: [0; 3],
            skipped_rendering_nothing: 0,
            iou_quartiles: [0.0; 3],
        };
        let mut skipped = Vec::new();
        let mut ious = Vec::with_capacity(pairs.len());
        for ((pair, &mask_pixels), overlap) in pairs.iter().zip(mask_pixels).zip(overlaps) {
            let level = pair.level.index();
            let iou = overlap.iou();
            ious.push(iou);
            report.pairs[level] += 1;
            if iou < threshold {
                skipped.push(*pair);
                report.skipped[level] += 1;
                if overlap.rendered_pixels(mask_pixels) == 0 {
                    report.skipped_rendering_nothing += 1;
                }
            }
        }
        ious.sort_by(f32::total_cmp);
        report.iou_quartiles = [0.25, 0.5, 0.75].map(|q| nearest_rank(&ious, q));
        (skipped, report)
    }

    /// Pairs left out, all levels.
    pub fn skipped_total(&self) -> usize {
        self.skipped.iter().sum()
    }
}

fn nearest_rank(sorted: &[f32], q: f32) -> f32 {
    match sorted.len() {
        0 => 0.0,
        n => sorted[((q * n as f32).ceil() as usize).clamp(1, n) - 1],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use segsplat_scene::Level;

    fn pair(level: Level, object_id: u32) -> SkippedPair {
        SkippedPair {
            train_view: 0,
            level,
            object_id,
        }
    }

    #[test]
    fn rendered_pixels_follow_from_the_counts() {
        // Mask 10 pixels, render 6, 4 shared: union 12.
        let overlap = PairOverlap {
            intersection: 4,
            union: 12,
        };
        assert_eq!(overlap.rendered_pixels(10), 6);
        assert!((overlap.iou() - 1.0 / 3.0).abs() < 1e-6);
        let nothing = PairOverlap {
            intersection: 0,
            union: 10,
        };
        assert_eq!((nothing.rendered_pixels(10), nothing.iou()), (0, 0.0));
    }

    #[test]
    fn judging_splits_partial_views_from_objects_that_render_nothing() {
        let pairs = [
            pair(Level::Small, 1),
            pair(Level::Small, 2),
            pair(Level::Middle, 3),
            pair(Level::Large, 4),
        ];
        let overlaps = [
            // Fits: IoU 0.9.
            PairOverlap {
                intersection: 9,
                union: 10,
            },
            // Renders nothing where its mask is.
            PairOverlap {
                intersection: 0,
                union: 8,
            },
            // A partial view: the render covers far more than the mask (IoU 0.2).
            PairOverlap {
                intersection: 2,
                union: 10,
            },
            // Fits: IoU 0.5.
            PairOverlap {
                intersection: 5,
                union: 10,
            },
        ];
        let mask_pixels = [10, 8, 2, 8];
        let (skipped, report) =
            PartialFilterReport::judge(300, 0.3, &pairs, &mask_pixels, &overlaps);
        assert_eq!(skipped, vec![pairs[1], pairs[2]]);
        assert_eq!(report.pairs, [2, 1, 1]);
        assert_eq!(report.skipped, [1, 1, 0]);
        assert_eq!(report.skipped_total(), 2);
        assert_eq!(report.skipped[Level::Middle.index()], 1);
        assert_eq!(report.skipped_rendering_nothing, 1);
        assert_eq!(report.iou_quartiles, [0.0, 0.2, 0.5]);
        assert_eq!(report.after_step, 300);
    }

    #[test]
    fn no_pairs_report_zeros() {
        let (skipped, report) = PartialFilterReport::judge(10, 0.3, &[], &[], &[]);
        assert!(skipped.is_empty());
        assert_eq!(report.iou_quartiles, [0.0; 3]);
    }
}
