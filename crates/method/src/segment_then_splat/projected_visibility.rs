//! An occlusion test for sparse points that have no COLMAP track and are projected into every
//! view instead: without it, a mask collects the points of everything its object hides, and
//! those links tie occluders to what they occlude.
//!
//! There is no depth map at this stage, so each mask's depth comes from the points falling in it:
//! its *front* is a low percentile of their depths (most of a mask's points that are visible
//! are its own object's front surface, which is nearer than its back and than anything behind
//! it). A projected point counts for a mask only when it is not much farther than that front.

/// Percentile of a mask's projected-point depths taken as its front (0.2: low enough to sit on
/// the visible surface when up to ~80% of the points are hidden ones, high enough that a few
/// stray nearer points on its outline do not set it).
const FRONT_PERCENTILE: f32 = 0.2;

/// Keeps, per mask, the projected points at most `(1 + tolerance)` times as deep as the mask's
/// front; `hits[point]` lists the masks a point falls in, `projected[point]` whether it was
/// projected (tracked points were seen there and always count), `depth(point, mask)` its depth
/// in that mask's view.
pub(super) fn keep_front_hits(
    hits: &mut [Vec<usize>],
    mask_count: usize,
    projected: &[bool],
    depth: impl Fn(usize, usize) -> f32,
    tolerance: f32,
) {
    let mut depths_in_mask: Vec<Vec<f32>> = vec![Vec::new(); mask_count];
    for (point, masks) in hits.iter().enumerate() {
        if projected.get(point).copied().unwrap_or(false) {
            for &mask in masks {
                depths_in_mask[mask].push(depth(point, mask));
            }
        }
    }
    let front: Vec<f32> = depths_in_mask
        .into_iter()
        .map(|mut depths| {
            if depths.is_empty() {
                return f32::INFINITY;
            }
            depths.sort_unstable_by(f32::total_cmp);
            let rank = ((depths.len() - 1) as f32 * FRONT_PERCENTILE).round() as usize;
            depths[rank]
        })
        .collect();
    for (point, masks) in hits.iter_mut().enumerate() {
        if projected.get(point).copied().unwrap_or(false) {
            masks.retain(|&mask| depth(point, mask) <= front[mask] * (1.0 + tolerance));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_far_behind_a_mask_front_are_dropped() {
        // Mask 0: eight points at depth 3.6-3.7 (its surface), two at 5 (hidden behind it).
        let depths = [3.6, 3.62, 3.64, 3.66, 3.68, 3.7, 3.6, 3.65, 5.0, 5.0];
        let mut hits = vec![vec![0]; depths.len()];
        let projected = vec![true; depths.len()];
        keep_front_hits(&mut hits, 1, &projected, |point, _| depths[point], 0.1);
        let kept = hits.iter().filter(|masks| !masks.is_empty()).count();
        assert_eq!(kept, 8);
        assert!(hits[8].is_empty() && hits[9].is_empty());
    }
}
