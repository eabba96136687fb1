//! Non-maximum suppression for one level's candidate masks: SAM's box NMS, then Segment then
//! Splat's mask NMS (duplicates, low scores, inner masks).
//!
//! The released mask NMS is a Python double loop over mask pairs, each pair a full-image
//! logical AND/OR. Here the pairs are computed in parallel (rayon) on bitsets, and a pair is only
//! counted when its bounding boxes overlap and its areas leave a rule able to fire; counting touches
//! only the words under the boxes' overlap.

use rayon::prelude::*;

use super::mask::{BitMask, BoundingBox};

/// Greedy box NMS (torchvision's `nms`, as SAM uses it): visit boxes by score, best first (ties
/// by index), and keep a box unless its IoU with an already kept box exceeds `iou_threshold`.
/// Returns kept indices, best first. Boxes only, so even 1000 candidates take microseconds.
pub fn box_nms(boxes: &[BoundingBox], scores: &[f32], iou_threshold: f32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..boxes.len().min(scores.len())).collect();
    order.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]).then(a.cmp(&b)));
    let mut kept: Vec<usize> = Vec::new();
    for candidate in order {
        if kept
            .iter()
            .all(|&kept_index| boxes[kept_index].iou(&boxes[candidate]) <= iou_threshold)
        {
            kept.push(candidate);
        }
    }
    kept
}

/// Segment then Splat's mask NMS rules (released `mask_nms(iou_thr=0.8, score_thr=0.7,
/// inner_thr=0.5)`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MaskNmsConfig {
    /// A mask whose IoU with a kept, higher-scored mask is above this is a duplicate.
    pub duplicate_iou: f32,
    /// Masks with `score <= min_score` are dropped (`score = stability x predicted IoU`).
    pub min_score: f32,
    /// Inner rule: a mask covered by another to at least this fraction of its own area ...
    pub inner_covered_fraction: f32,
    /// ... while it covers less than this fraction of that other mask, is dropped.
    pub outer_covered_fraction: f32,
}

impl Default for MaskNmsConfig {
    fn default() -> Self {
        MaskNmsConfig {
            duplicate_iou: 0.8,
            min_score: 0.7,
            inner_covered_fraction: 0.85,
            outer_covered_fraction: 0.5,
        }
    }
}

/// What mask NMS needs of a candidate.
#[derive(Debug, Clone, Copy)]
pub struct NmsCandidate<'a> {
    pub mask: &'a BitMask,
    pub bbox: BoundingBox,
    pub area: u64,
    pub score: f32,
}

/// How two candidates relate, found by counting their intersection.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct PairRelation {
    duplicate: bool,
    first_is_inner: bool,
    second_is_inner: bool,
}

/// Whether `inner` (area `inner_area`) lies inside `outer` by the inner rule, given their
/// intersection.
fn is_inner(intersection: u64, inner_area: u64, outer_area: u64, config: &MaskNmsConfig) -> bool {
    let intersection = intersection as f64;
    intersection >= f64::from(config.inner_covered_fraction) * inner_area as f64
        && intersection < f64::from(config.outer_covered_fraction) * outer_area as f64
}

/// The relation of a pair, or `None` when no rule can fire. Cheap rejections first: disjoint
/// boxes, then bounds on the intersection from the box overlap and the areas.
fn relate(
    first: &NmsCandidate<'_>,
    second: &NmsCandidate<'_>,
    config: &MaskNmsConfig,
) -> Option<PairRelation> {
    let overlap = first.bbox.intersection(&second.bbox)?;
    let (small_area, large_area) = if first.area <= second.area {
        (first.area, second.area)
    } else {
        (second.area, first.area)
    };
    // Upper bound on the intersection: the smaller mask and the box overlap.
    let max_intersection = small_area.min(overlap.area()) as f64;
    // IoU <= intersection / larger area: a duplicate needs max_intersection > t * larger area.
    let duplicate_possible = max_intersection > f64::from(config.duplicate_iou) * large_area as f64;
    // Only the smaller mask can be inner (it must cover < outer fraction of a mask with at least
    // inner fraction of its area in common).
    let inner_possible = max_intersection
        >= f64::from(config.inner_covered_fraction) * small_area as f64
        && f64::from(config.inner_covered_fraction) * (small_area as f64)
            < f64::from(config.outer_covered_fraction) * large_area as f64;
    if !duplicate_possible && !inner_possible {
        return None;
    }
    let intersection = first.mask.intersection_area_within(second.mask, &overlap);
    let union = first.area + second.area - intersection;
    let relation = PairRelation {
        duplicate: union > 0
            && intersection as f64 > f64::from(config.duplicate_iou) * union as f64,
        first_is_inner: is_inner(intersection, first.area, second.area, config),
        second_is_inner: is_inner(intersection, second.area, first.area, config),
    };
    (relation != PairRelation::default()).then_some(relation)
}

/// Mask NMS over one level's candidates. Returns the indices of the kept candidates, best score
/// first (ties by index).
///
/// Rules, read from the released `mask_nms` / `masks_update` / `filter`:
/// 1. Low score: `score <= min_score` is dropped. Unlike the released code, a dropped mask does
///    not suppress others, and there is no "keep the top 3 when nothing passes" fallback.
/// 2. Inner masks: when mask A covers >= 85% of mask B (intersection >= 0.85 area(B)) while B
///    covers < 50% of A (intersection < 0.5 area(A)), **B, the inner one, is dropped, whatever the
///    scores**. The released code writes that pair's entry into the column of the inner mask in
///    both the upper and the lower triangle of its score-sorted matrix, so it is the inner mask
///    that fails `keep_inner_*` either way. Per level, one pixel belongs to one object, and the
///    nested part is left to a finer level.
/// 3. Duplicates: IoU > `duplicate_iou` with a higher-scored mask that is kept. This is greedy
///    NMS: a suppressed mask cannot suppress a third one, where the released matrix form lets
///    any higher-scored mask do so (losing objects along chains of near-duplicates). Masks dropped
///    by rules 1 and 2 do not suppress.
pub fn mask_nms(candidates: &[NmsCandidate<'_>], config: &MaskNmsConfig) -> Vec<usize> {
    let mut order: Vec<usize> = (0..candidates.len())
        .filter(|&index| candidates[index].score > config.min_score && candidates[index].area > 0)
        .collect();
    order.sort_by(|&a, &b| {
        candidates[b]
            .score
            .total_cmp(&candidates[a].score)
            .then(a.cmp(&b))
    });
    let ranked: Vec<&NmsCandidate<'_>> = order.iter().map(|&index| &candidates[index]).collect();

    // Pairwise relations in parallel; each rank pairs with the ranks after it (rayon's work
    // stealing evens out the triangle).
    let relations: Vec<(usize, usize, PairRelation)> = (0..ranked.len())
        .into_par_iter()
        .flat_map_iter(|first| {
            let ranked = &ranked;
            (first + 1..ranked.len()).filter_map(move |second| {
                relate(ranked[first], ranked[second], config)
                    .map(|relation| (first, second, relation))
            })
        })
        .collect();

    let mut is_inner_mask = vec![false; ranked.len()];
    let mut better_duplicates_from_rank: Vec<Vec<usize>> = vec![Vec::new(); ranked.len()];
    for &(first, second, relation) in &relations {
        is_inner_mask[first] |= relation.first_is_inner;
        is_inner_mask[second] |= relation.second_is_inner;
        if relation.duplicate {
            better_duplicates_from_rank[second].push(first);
        }
    }
    let mut kept_rank = vec![false; ranked.len()];
    for rank in 0..ranked.len() {
        kept_rank[rank] = !is_inner_mask[rank]
            && !better_duplicates_from_rank[rank]
                .iter()
                .any(|&better| kept_rank[better]);
    }
    order
        .into_iter()
        .zip(kept_rank)
        .filter_map(|(index, kept)| kept.then_some(index))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: u32 = 64;

    fn disc(cx: f32, cy: f32, radius: f32) -> BitMask {
        let mut mask = BitMask::new(SIZE, SIZE);
        for y in 0..SIZE {
            for x in 0..SIZE {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                mask.set(x, y, dx * dx + dy * dy <= radius * radius);
            }
        }
        mask
    }

    fn candidate(mask: &BitMask, score: f32) -> NmsCandidate<'_> {
        NmsCandidate {
            mask,
            bbox: mask.bounding_box().expect("non-empty"),
            area: mask.area(),
            score,
        }
    }

    #[test]
    fn box_nms_keeps_the_higher_score() {
        let boxes = [
            BoundingBox {
                x_min: 0,
                y_min: 0,
                x_max: 9,
                y_max: 9,
            },
            BoundingBox {
                x_min: 0,
                y_min: 0,
                x_max: 9,
                y_max: 10,
            },
            BoundingBox {
                x_min: 30,
                y_min: 30,
                x_max: 39,
                y_max: 39,
            },
        ];
        // Box 1 scores higher than its near-copy box 0, so box 0 goes.
        assert_eq!(box_nms(&boxes, &[0.8, 0.9, 0.5], 0.7), vec![1, 2]);
        assert_eq!(box_nms(&boxes, &[0.95, 0.9, 0.5], 0.7), vec![0, 2]);
        // IoU 100/110 = 0.909 is not above 0.95: both stay.
        assert_eq!(box_nms(&boxes, &[0.8, 0.9, 0.5], 0.95), vec![1, 0, 2]);
    }

    #[test]
    fn duplicate_with_lower_score_is_dropped() {
        let a = disc(20.0, 20.0, 10.0);
        let b = disc(20.5, 20.0, 10.0); // IoU ~0.97
        let far = disc(50.0, 50.0, 8.0);
        let candidates = [
            candidate(&a, 0.8),
            candidate(&b, 0.9),
            candidate(&far, 0.75),
        ];
        assert_eq!(mask_nms(&candidates, &MaskNmsConfig::default()), vec![1, 2]);
        // Below the duplicate IoU both stay: a disc shifted by 6 px has IoU ~0.45.
        let c = disc(26.0, 20.0, 10.0);
        let candidates = [candidate(&a, 0.8), candidate(&c, 0.9)];
        assert_eq!(mask_nms(&candidates, &MaskNmsConfig::default()), vec![1, 0]);
    }

    #[test]
    fn low_score_is_dropped_even_when_alone() {
        let a = disc(20.0, 20.0, 10.0);
        let b = disc(45.0, 45.0, 10.0);
        let candidates = [candidate(&a, 0.7), candidate(&b, 0.71)];
        assert_eq!(mask_nms(&candidates, &MaskNmsConfig::default()), vec![1]);
    }

    #[test]
    fn inner_mask_is_dropped_whatever_its_score() {
        let outer = disc(32.0, 32.0, 25.0);
        let inner = disc(30.0, 30.0, 8.0); // fully inside, ~10% of the outer area
        for (outer_score, inner_score) in [(0.9, 0.8), (0.8, 0.9)] {
            let candidates = [
                candidate(&outer, outer_score),
                candidate(&inner, inner_score),
            ];
            assert_eq!(
                mask_nms(&candidates, &MaskNmsConfig::default()),
                vec![0],
                "outer {outer_score}, inner {inner_score}"
            );
        }
        // Covering more than half of the other is not "inner": a disc of radius 20 inside 25
        // covers 64% of it, so both stay (IoU 0.64 is no duplicate either).
        let big_inside = disc(32.0, 32.0, 20.0);
        let candidates = [candidate(&outer, 0.9), candidate(&big_inside, 0.8)];
        assert_eq!(mask_nms(&candidates, &MaskNmsConfig::default()), vec![0, 1]);
        // Mostly outside (less than 85% covered): kept.
        let straddling = disc(56.0, 32.0, 8.0); // ~60% inside
        let candidates = [candidate(&outer, 0.9), candidate(&straddling, 0.8)];
        assert_eq!(mask_nms(&candidates, &MaskNmsConfig::default()), vec![0, 1]);
    }

    #[test]
    fn suppressed_duplicates_do_not_suppress_further() {
        // a ~ b and b ~ c are duplicates, a and c are not: greedy keeps a and c.
        let mut a = BitMask::new(SIZE, SIZE);
        let mut b = BitMask::new(SIZE, SIZE);
        let mut c = BitMask::new(SIZE, SIZE);
        for y in 0..20 {
            for x in 0..40 {
                a.set(x, y, x < 30);
                b.set(x, y, (3..33).contains(&x));
                c.set(x, y, (6..36).contains(&x));
            }
        }
        assert!(a.iou(&b).expect("same size") > 0.8 && b.iou(&c).expect("same size") > 0.8);
        assert!(a.iou(&c).expect("same size") <= 0.8);
        let candidates = [candidate(&a, 0.95), candidate(&b, 0.9), candidate(&c, 0.85)];
        assert_eq!(mask_nms(&candidates, &MaskNmsConfig::default()), vec![0, 2]);
    }
}
