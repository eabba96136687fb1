//! The output of every mask generator: per level, masks with their scores, and the conversion of
//! a level into an instance-id image (one object per pixel).

use super::mask::{BitMask, BoundingBox};
use segsplat_scene::Level;

/// One object mask of one level, with the evidence that it is a good one.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoredMask {
    pub mask: BitMask,
    /// Set pixels of `mask`.
    pub area: u64,
    pub bbox: BoundingBox,
    /// The decoder's predicted IoU (1 for classical and user masks).
    pub predicted_iou: f32,
    /// SAM's stability score (1 for classical and user masks).
    pub stability: f32,
    /// `stability x predicted_iou`, what mask NMS ranks and thresholds by.
    pub score: f32,
    /// The point prompt (`[x, y]` pixels) that produced the mask, for automatic masks.
    pub point: Option<[f32; 2]>,
    /// The id this mask carried in its source instance-id image (user masks), so ids that agree
    /// across a user's views stay recognisable; `None` for generated masks.
    pub instance_id: Option<u32>,
}

impl ScoredMask {
    /// A mask known to be right by construction (classical regions, user masks): all scores 1.
    /// `None` for an empty mask.
    pub fn certain(mask: BitMask, instance_id: Option<u32>) -> Option<ScoredMask> {
        let bbox = mask.bounding_box()?;
        Some(ScoredMask {
            area: mask.area(),
            mask,
            bbox,
            predicted_iou: 1.0,
            stability: 1.0,
            score: 1.0,
            point: None,
            instance_id,
        })
    }
}

/// The masks of one frame at the three levels (index with [`Level::index`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameMasks {
    pub levels: [Vec<ScoredMask>; 3],
}

impl FrameMasks {
    pub fn level(&self, level: Level) -> &[ScoredMask] {
        &self.levels[level.index()]
    }

    /// The instance-id image of one level: see [`instance_ids_from_masks`].
    pub fn instance_ids(&self, level: Level, width: u32, height: u32) -> Vec<u32> {
        instance_ids_from_masks(self.level(level), width, height)
    }
}

/// Paints a level's masks into a row-major `width x height` id image: mask `i` of the slice gets
/// id `i + 1`, 0 is no object, and every pixel belongs to at most one object.
///
/// Where masks overlap, the smaller mask wins (masks are painted largest first), as the
/// Segment-then-Splat / LangSplat lineage does: after mask NMS the overlaps left are partial, and
/// letting the larger mask win would erase small objects that sit on larger ones. Equal areas:
/// the higher-scored (earlier) mask wins. Masks of another size are skipped.
pub fn instance_ids_from_masks(masks: &[ScoredMask], width: u32, height: u32) -> Vec<u32> {
    let mut ids = vec![0u32; width as usize * height as usize];
    let mut paint_order: Vec<usize> = (0..masks.len()).collect();
    // Largest first; among equal areas the later (lower-scored) first so the earlier one wins.
    paint_order.sort_by(|&a, &b| masks[b].area.cmp(&masks[a].area).then(b.cmp(&a)));
    for index in paint_order {
        let scored = &masks[index];
        if (scored.mask.width(), scored.mask.height()) != (width, height) {
            continue;
        }
        let id = index as u32 + 1;
        for y in scored.bbox.y_min..=scored.bbox.y_max {
            let row_start = y as usize * width as usize;
            for x in scored.mask.row_set_columns(y) {
                ids[row_start + x as usize] = id;
            }
        }
    }
    ids
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(size: u32, x0: u32, y0: u32, side: u32, score: f32) -> ScoredMask {
        let mut mask = BitMask::new(size, size);
        for y in y0..y0 + side {
            for x in x0..x0 + side {
                mask.set(x, y, true);
            }
        }
        let mut scored = ScoredMask::certain(mask, None).expect("non-empty");
        scored.score = score;
        scored
    }

    #[test]
    fn smaller_mask_wins_overlaps_regardless_of_order() {
        // The large square scores higher and comes first; the small one must still show.
        let masks = vec![square(10, 0, 0, 8, 0.9), square(10, 2, 2, 3, 0.8)];
        let ids = instance_ids_from_masks(&masks, 10, 10);
        assert_eq!(ids[3 * 10 + 3], 2, "inside the small square");
        assert_eq!(ids[0], 1, "large square outside the small one");
        assert_eq!(ids[9 * 10 + 9], 0, "uncovered");
        let small_pixels = ids.iter().filter(|&&id| id == 2).count();
        assert_eq!(small_pixels, 9);
        assert_eq!(ids.iter().filter(|&&id| id == 1).count(), 64 - 9);
    }

    #[test]
    fn equal_areas_go_to_the_higher_score() {
        let masks = vec![square(6, 0, 0, 3, 0.9), square(6, 1, 1, 3, 0.5)];
        let ids = instance_ids_from_masks(&masks, 6, 6);
        assert_eq!(ids[6 + 1], 1);
        assert_eq!(ids[3 * 6 + 3], 2);
    }
}
