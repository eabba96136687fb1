//! Stage 1 for posed static views, after linking: groups of local masks become global objects
//! of one level, duplicates are dropped, and each view's objects are painted into one id map
//! (every pixel in at most one object), with ids 1..N.

use std::collections::HashMap;

use super::mask_links::{Grouping, LocalMask};
use segsplat_vision::segment::{
    BitMask, BoundingBox, MaskError, ScoredMask, instance_ids_from_masks,
};

/// One object across views: per view where it appears, the union of its local masks there.
#[derive(Debug, Clone)]
pub(super) struct GlobalObject {
    /// (view, mask, bounding box), in increasing view order.
    pub parts: Vec<(usize, BitMask, BoundingBox)>,
    /// Pixels over all its views.
    pub area: u64,
}

/// What became of the groups.
#[derive(Debug, Clone, Default)]
pub(super) struct ObjectsFromGroups {
    pub objects: Vec<GlobalObject>,
    /// Unlinked masks under the new-object area, left unlabelled.
    pub too_small: usize,
}

/// The objects the groups make. A group of one mask that links to nothing is a new object only
/// when `min_new_area(view)` pixels or more (docs/method.md's uncovered-area rule: 5000 px at about
/// 1000 px width); smaller ones are left unlabelled, since nothing but one view vouches for
/// them and they are too small to matter.
pub(super) fn objects_from_groups(
    masks: &[LocalMask],
    grouping: &Grouping,
    min_new_area: impl Fn(usize) -> f64,
) -> Result<ObjectsFromGroups, MaskError> {
    let mut result = ObjectsFromGroups::default();
    for group in &grouping.groups {
        if let [single] = group.as_slice() {
            let local = &masks[*single];
            if !grouping.linked[*single] && (local.area as f64) < min_new_area(local.view) {
                result.too_small += 1;
                continue;
            }
        }
        let mut parts: Vec<(usize, BitMask, BoundingBox)> = Vec::new();
        for &index in group {
            let local = &masks[index];
            match parts.iter_mut().find(|(view, _, _)| *view == local.view) {
                Some((_, mask, bbox)) => {
                    mask.union_with(&local.mask)?;
                    *bbox = mask.bounding_box().unwrap_or(*bbox);
                }
                None => parts.push((local.view, local.mask.clone(), local.bbox)),
            }
        }
        parts.sort_by_key(|(view, _, _)| *view);
        let area = parts.iter().map(|(_, mask, _)| mask.area()).sum();
        result.objects.push(GlobalObject { parts, area });
    }
    Ok(result)
}

/// Drops duplicates: two objects whose masks overlap with IoU above `max_iou`, pooled over the
/// views where both appear (summed intersections over summed unions), are one object tracked
/// twice; the smaller (fewer pixels over all views) goes, globally, as docs/method.md's stage 1 step 4
/// says. Pairs are judged most-overlapping first; a dropped object drops nothing further.
/// Returns the objects kept (in their order) and how many were dropped.
///
/// Generators whose masks overlap within a view (SAM-family) make such pairs; the classical
/// generator's regions are disjoint, so it never does.
pub(super) fn drop_duplicates(
    objects: Vec<GlobalObject>,
    view_count: usize,
    max_iou: f64,
) -> Result<(Vec<GlobalObject>, usize), MaskError> {
    let mut parts_in_view: Vec<Vec<(usize, &BitMask, &BoundingBox)>> = vec![Vec::new(); view_count];
    for (object, global) in objects.iter().enumerate() {
        for (view, mask, bbox) in &global.parts {
            if let Some(list) = parts_in_view.get_mut(*view) {
                list.push((object, mask, bbox));
            }
        }
    }
    // Per pair (a < b) seen together: (intersection, union) summed over shared views.
    let mut overlap: HashMap<(usize, usize), (u64, u64)> = HashMap::new();
    for parts in &parts_in_view {
        for (position, &(a, mask_a, bbox_a)) in parts.iter().enumerate() {
            for &(b, mask_b, bbox_b) in &parts[position + 1..] {
                let intersection = match bbox_a.intersection(bbox_b) {
                    Some(_) => mask_a.intersection_area(mask_b)?,
                    None => 0,
                };
                let union = mask_a.area() + mask_b.area() - intersection;
                let entry = overlap.entry((a.min(b), a.max(b))).or_default();
                entry.0 += intersection;
                entry.1 += union;
            }
        }
    }
    let mut duplicates: Vec<((usize, usize), f64)> = overlap
        .into_iter()
        .filter(|(_, (intersection, _))| *intersection > 0)
        .map(|(pair, (intersection, union))| (pair, intersection as f64 / union as f64))
        .filter(|(_, iou)| *iou > max_iou)
        .collect();
    duplicates.sort_by(|(pair_a, iou_a), (pair_b, iou_b)| {
        iou_b.total_cmp(iou_a).then(pair_a.cmp(pair_b))
    });
    let mut dropped = vec![false; objects.len()];
    for ((a, b), _) in duplicates {
        if dropped[a] || dropped[b] {
            continue;
        }
        let smaller = if objects[b].area > objects[a].area {
            a
        } else {
            b
        };
        dropped[smaller] = true;
    }
    let dropped_count = dropped.iter().filter(|&&d| d).count();
    let kept = objects
        .into_iter()
        .zip(dropped)
        .filter_map(|(object, dropped)| (!dropped).then_some(object))
        .collect();
    Ok((kept, dropped_count))
}

/// Per view, the row-major id map of `objects` (object `i` of the slice gets id `i + 1`), every
/// pixel in at most one object: where objects overlap in a view, the smaller one there wins, as
/// [`instance_ids_from_masks`] paints generator masks.
pub(super) fn paint_objects(objects: &[GlobalObject], view_sizes: &[(u32, u32)]) -> Vec<Vec<u32>> {
    let mut in_view: Vec<Vec<(u32, ScoredMask)>> = vec![Vec::new(); view_sizes.len()];
    for (index, object) in objects.iter().enumerate() {
        for (view, mask, _) in &object.parts {
            if let (Some(list), Some(scored)) = (
                in_view.get_mut(*view),
                ScoredMask::certain(mask.clone(), None),
            ) {
                list.push((index as u32 + 1, scored));
            }
        }
    }
    in_view
        .into_iter()
        .zip(view_sizes)
        .map(|(list, &(width, height))| {
            let (ids, masks): (Vec<u32>, Vec<ScoredMask>) = list.into_iter().unzip();
            instance_ids_from_masks(&masks, width, height)
                .into_iter()
                .map(|local| {
                    if local == 0 {
                        0
                    } else {
                        ids[local as usize - 1]
                    }
                })
                .collect()
        })
        .collect()
}

/// Largest object (pixels over all views) first, so ids 1..N run from large to small; ties keep
/// their order.
pub(super) fn sort_largest_first(objects: &mut [GlobalObject]) {
    objects.sort_by_key(|object| std::cmp::Reverse(object.area));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(size: u32, x0: u32, y0: u32, side: u32) -> BitMask {
        let mut mask = BitMask::new(size, size);
        for y in y0..y0 + side {
            for x in x0..x0 + side {
                mask.set(x, y, true);
            }
        }
        mask
    }

    fn object(parts: Vec<(usize, BitMask)>) -> GlobalObject {
        let area = parts.iter().map(|(_, m)| m.area()).sum();
        GlobalObject {
            parts: parts
                .into_iter()
                .map(|(view, mask)| {
                    let bbox = mask.bounding_box().expect("non-empty");
                    (view, mask, bbox)
                })
                .collect(),
            area,
        }
    }

    #[test]
    fn the_smaller_of_two_overlapping_objects_is_dropped() {
        let big = object(vec![(0, square(8, 0, 0, 6)), (1, square(8, 0, 0, 6))]);
        // IoU 25/36 with the big one in view 0.
        let twin = object(vec![(0, square(8, 0, 0, 5))]);
        let apart = object(vec![(0, square(8, 6, 6, 2))]);
        let (kept, dropped) = drop_duplicates(vec![twin, big, apart], 2, 0.5).expect("sizes");
        assert_eq!(dropped, 1);
        assert_eq!(kept.len(), 2);
        assert_eq!(kept[0].area, 72);
    }

    #[test]
    fn painting_keeps_one_object_per_pixel_with_the_smaller_on_top() {
        let objects = vec![
            object(vec![(0, square(4, 0, 0, 4))]),
            object(vec![(0, square(4, 1, 1, 2))]),
        ];
        let maps = paint_objects(&objects, &[(4, 4)]);
        assert_eq!(maps[0][0], 1);
        assert_eq!(maps[0][5], 2);
        assert_eq!(maps[0].iter().filter(|&&id| id == 2).count(), 4);
    }
}
