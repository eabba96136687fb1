//! Positive points for a prompt: where a mask is deepest, so that a few pixels of motion or a
//! ragged edge still leave them on the object.

use crate::segment::{BitMask, BoundingBox};

/// Chamfer 3-4 distances to the nearest pixel outside `mask`, over `bbox` grown by one pixel
/// (outside the box is outside the mask). Row-major over that grown window.
fn chamfer_depth(mask: &BitMask, bbox: &BoundingBox) -> (Vec<u32>, usize) {
    let width = bbox.width() as usize + 2;
    let height = bbox.height() as usize + 2;
    let mut depth = vec![0u32; width * height];
    for y in bbox.y_min..=bbox.y_max {
        let row = (y - bbox.y_min + 1) as usize * width;
        for x in mask.row_set_columns(y) {
            if (bbox.x_min..=bbox.x_max).contains(&x) {
                depth[row + (x - bbox.x_min + 1) as usize] = u32::MAX;
            }
        }
    }
    // The one-pixel frame stays 0, so the neighbours read below always exist.
    for y in 1..height - 1 {
        for x in 1..width - 1 {
            let index = y * width + x;
            if depth[index] == 0 {
                continue;
            }
            let around = [
                depth[index - 1].saturating_add(3),
                depth[index - width].saturating_add(3),
                depth[index - width - 1].saturating_add(4),
                depth[index - width + 1].saturating_add(4),
            ];
            depth[index] = around.into_iter().fold(depth[index], u32::min);
        }
    }
    for y in (1..height - 1).rev() {
        for x in (1..width - 1).rev() {
            let index = y * width + x;
            if depth[index] == 0 {
                continue;
            }
            let around = [
                depth[index + 1].saturating_add(3),
                depth[index + width].saturating_add(3),
                depth[index + width + 1].saturating_add(4),
                depth[index + width - 1].saturating_add(4),
            ];
            depth[index] = around.into_iter().fold(depth[index], u32::min);
        }
    }
    (depth, width)
}

/// `count` points (`[x, y]` pixel centres) inside `mask`, whose box is `bbox`: first the pixel
/// farthest from the edge, then, greedily, the pixel of the deep half (at least half the deepest
/// depth) farthest from the points already chosen. When the deep half has fewer distinct pixels,
/// the deepest point repeats: every prompt keeps the same number of points, so prompts batch.
pub(super) fn interior_points(mask: &BitMask, bbox: &BoundingBox, count: usize) -> Vec<[f32; 2]> {
    if count == 0 {
        return Vec::new();
    }
    let (depth, window_width) = chamfer_depth(mask, bbox);
    let deepest = depth
        .iter()
        .enumerate()
        .max_by_key(|&(index, &value)| (value, std::cmp::Reverse(index)))
        .map_or(0, |(index, _)| index);
    let to_pixel = |index: usize| {
        [
            (index % window_width) as i64 - 1 + i64::from(bbox.x_min),
            (index / window_width) as i64 - 1 + i64::from(bbox.y_min),
        ]
    };
    let deep: Vec<[i64; 2]> = depth
        .iter()
        .enumerate()
        .filter(|&(_, &value)| value > 0 && value * 2 >= depth[deepest])
        .map(|(index, _)| to_pixel(index))
        .collect();
    let mut chosen = vec![to_pixel(deepest)];
    let mut nearest: Vec<i64> = deep.iter().map(|&p| squared(p, chosen[0])).collect();
    while chosen.len() < count {
        let Some((index, &distance)) = nearest
            .iter()
            .enumerate()
            .max_by_key(|&(index, &distance)| (distance, std::cmp::Reverse(index)))
        else {
            break;
        };
        if distance == 0 {
            break;
        }
        let point = deep[index];
        chosen.push(point);
        for (slot, &other) in nearest.iter_mut().zip(&deep) {
            *slot = (*slot).min(squared(other, point));
        }
    }
    let deepest_point = chosen[0];
    chosen.resize(count, deepest_point);
    chosen
        .into_iter()
        .map(|[x, y]| [x as f32 + 0.5, y as f32 + 0.5])
        .collect()
}

fn squared(a: [i64; 2], b: [i64; 2]) -> i64 {
    (a[0] - b[0]).pow(2) + (a[1] - b[1]).pow(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring_of(width: u32, height: u32, inside: impl Fn(u32, u32) -> bool) -> BitMask {
        let mut mask = BitMask::new(width, height);
        for y in 0..height {
            for x in 0..width {
                mask.set(x, y, inside(x, y));
            }
        }
        mask
    }

    #[test]
    fn the_first_point_is_the_deepest_and_all_lie_inside() {
        // A 21x11 rectangle: deepest along its middle row.
        let mask = ring_of(40, 30, |x, y| (5..26).contains(&x) && (10..21).contains(&y));
        let bbox = mask.bounding_box().expect("non-empty");
        let points = interior_points(&mask, &bbox, 3);
        assert_eq!(points.len(), 3);
        assert_eq!(points[0][1], 15.5, "middle row");
        for [x, y] in &points {
            assert!(mask.get(*x as u32, *y as u32));
        }
        assert_ne!(points[1], points[0], "spread over the interior");
    }

    #[test]
    fn an_annulus_is_never_prompted_in_its_hole() {
        let mask = ring_of(41, 41, |x, y| {
            let d = (x as f32 - 20.0).powi(2) + (y as f32 - 20.0).powi(2);
            (64.0..=324.0).contains(&d)
        });
        let bbox = mask.bounding_box().expect("non-empty");
        for [x, y] in interior_points(&mask, &bbox, 4) {
            assert!(mask.get(x as u32, y as u32), "({x}, {y}) off the ring");
        }
    }

    #[test]
    fn a_single_pixel_repeats_to_the_requested_count() {
        let mask = ring_of(5, 5, |x, y| (x, y) == (4, 0));
        let bbox = mask.bounding_box().expect("non-empty");
        assert_eq!(interior_points(&mask, &bbox, 2), vec![[4.5, 0.5]; 2]);
        assert!(interior_points(&mask, &bbox, 0).is_empty());
    }
}
