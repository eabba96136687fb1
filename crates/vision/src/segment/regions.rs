//! SAM's `remove_small_regions`: fill holes and drop islands smaller than an area, with
//! 8-connected components as `cv2.connectedComponentsWithStats(..., 8)` finds them. Work is
//! confined to the mask's bounding box (plus a one-pixel ring for holes), so a small mask in a
//! large image costs little.

use super::mask::{BitMask, BoundingBox};

/// Connected components (8-connectivity) of the `true` cells of a `width x height` grid.
/// Returns the label of every cell (`u32::MAX` for `false` cells) and each component's size.
fn label_components(cells: &[bool], width: usize, height: usize) -> (Vec<u32>, Vec<u64>) {
    const UNLABELLED: u32 = u32::MAX;
    let mut labels = vec![UNLABELLED; cells.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..cells.len() {
        if !cells[start] || labels[start] != UNLABELLED {
            continue;
        }
        let label = sizes.len() as u32;
        let mut size = 0u64;
        labels[start] = label;
        stack.push(start);
        while let Some(index) = stack.pop() {
            size += 1;
            let (x, y) = ((index % width) as isize, (index / width) as isize);
            for dy in -1..=1isize {
                for dx in -1..=1isize {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                        continue;
                    }
                    let neighbour = ny as usize * width + nx as usize;
                    if cells[neighbour] && labels[neighbour] == UNLABELLED {
                        labels[neighbour] = label;
                        stack.push(neighbour);
                    }
                }
            }
        }
        sizes.push(size);
    }
    (labels, sizes)
}

/// The cells of `window`, `true` where the mask equals `value`.
fn window_cells(mask: &BitMask, window: &BoundingBox, value: bool) -> Vec<bool> {
    let mut cells = Vec::with_capacity(window.area() as usize);
    for y in window.y_min..=window.y_max {
        for x in window.x_min..=window.x_max {
            cells.push(mask.get(x, y) == value);
        }
    }
    cells
}

/// Fills background components smaller than `min_area` pixels. Returns whether anything changed.
///
/// Background reaching past the bounding box joins the background outside the window; its size
/// counts every pixel outside the window. That equals SAM's full-image count unless the box spans
/// the whole image in one direction and splits the outside in two, where it can only call a
/// region big that SAM calls small (it fills less, never more).
pub fn fill_small_holes(mask: &mut BitMask, min_area: u64) -> bool {
    let Some(bbox) = mask.bounding_box() else {
        return false;
    };
    let window = bbox.expanded(1, mask.width(), mask.height());
    let (width, height) = (window.width() as usize, window.height() as usize);
    let (labels, mut sizes) = label_components(&window_cells(mask, &window, false), width, height);
    let outside_window = u64::from(mask.width()) * u64::from(mask.height()) - window.area();
    // Components touching the ring around the box are connected to the outside.
    let mut reaches_outside = vec![false; sizes.len()];
    for (index, &label) in labels.iter().enumerate() {
        if label == u32::MAX {
            continue;
        }
        let x = window.x_min + (index % width) as u32;
        let y = window.y_min + (index / width) as u32;
        let outside_box = x < bbox.x_min || x > bbox.x_max || y < bbox.y_min || y > bbox.y_max;
        if outside_box && !reaches_outside[label as usize] {
            reaches_outside[label as usize] = true;
            sizes[label as usize] += outside_window;
        }
    }
    let small: Vec<bool> = sizes.iter().map(|&size| size < min_area).collect();
    if !small.iter().any(|&is_small| is_small) {
        return false;
    }
    for (index, &label) in labels.iter().enumerate() {
        if label != u32::MAX && small[label as usize] {
            let x = window.x_min + (index % width) as u32;
            let y = window.y_min + (index / width) as u32;
            mask.set(x, y, true);
        }
    }
    true
}

/// Removes mask components smaller than `min_area` pixels; when every component is small, keeps
/// the largest (the first found on a tie), as SAM does. Returns whether anything changed.
pub fn remove_small_islands(mask: &mut BitMask, min_area: u64) -> bool {
    let Some(window) = mask.bounding_box() else {
        return false;
    };
    let (width, height) = (window.width() as usize, window.height() as usize);
    let (labels, sizes) = label_components(&window_cells(mask, &window, true), width, height);
    let mut keep: Vec<bool> = sizes.iter().map(|&size| size >= min_area).collect();
    if keep.iter().all(|&kept| kept) {
        return false;
    }
    if !keep.iter().any(|&kept| kept) {
        let largest =
            sizes.iter().enumerate().fold(
                0,
                |best, (label, &size)| if size > sizes[best] { label } else { best },
            );
        keep[largest] = true;
        if sizes.len() == 1 {
            return false;
        }
    }
    for (index, &label) in labels.iter().enumerate() {
        if label != u32::MAX && !keep[label as usize] {
            let x = window.x_min + (index % width) as u32;
            let y = window.y_min + (index / width) as u32;
            mask.set(x, y, false);
        }
    }
    true
}

/// SAM's post-processing order: holes first, then islands. Returns whether the mask changed.
pub fn remove_small_regions(mask: &mut BitMask, min_area: u64) -> bool {
    if min_area == 0 {
        return false;
    }
    let filled = fill_small_holes(mask, min_area);
    let removed = remove_small_islands(mask, min_area);
    filled || removed
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fill_rect(mask: &mut BitMask, x0: u32, y0: u32, x1: u32, y1: u32, value: bool) {
        for y in y0..=y1 {
            for x in x0..=x1 {
                mask.set(x, y, value);
            }
        }
    }

    #[test]
    fn small_holes_are_filled_and_large_ones_kept() {
        let mut mask = BitMask::new(40, 30);
        fill_rect(&mut mask, 5, 5, 34, 24, true);
        fill_rect(&mut mask, 8, 8, 9, 9, false); // 4-pixel hole
        fill_rect(&mut mask, 15, 10, 26, 20, false); // 132-pixel hole
        let before = mask.area();
        assert!(fill_small_holes(&mut mask, 10));
        assert_eq!(mask.area(), before + 4);
        assert!(!mask.get(20, 15), "large hole stays");
        assert!(mask.get(8, 8), "small hole filled");
    }

    #[test]
    fn background_outside_the_box_is_never_a_hole() {
        // A notch open to the outside of the box through the ring is not a hole.
        let mut mask = BitMask::new(20, 20);
        fill_rect(&mut mask, 2, 2, 17, 17, true);
        fill_rect(&mut mask, 2, 8, 4, 9, false); // notch touching the box's left edge
        let before = mask.clone();
        assert!(!fill_small_holes(&mut mask, 50));
        assert_eq!(mask, before);
    }

    #[test]
    fn hole_at_the_image_border_inside_the_box_is_filled() {
        // A U open towards the image's bottom edge: the gap only touches the image border, so
        // (as in SAM's full-image labelling) it is a small component and gets filled.
        let mut mask = BitMask::new(12, 10);
        fill_rect(&mut mask, 2, 2, 9, 9, true);
        fill_rect(&mut mask, 5, 7, 6, 9, false);
        assert!(fill_small_holes(&mut mask, 10));
        assert!(mask.get(5, 9));
    }

    #[test]
    fn small_islands_are_removed_but_the_largest_survives_alone() {
        let mut mask = BitMask::new(30, 30);
        fill_rect(&mut mask, 2, 2, 12, 12, true); // 121
        fill_rect(&mut mask, 20, 20, 21, 21, true); // 4
        assert!(remove_small_islands(&mut mask, 10));
        assert_eq!(mask.area(), 121);
        let mut tiny = BitMask::new(30, 30);
        fill_rect(&mut tiny, 1, 1, 2, 2, true); // 4
        fill_rect(&mut tiny, 20, 20, 22, 21, true); // 6
        assert!(remove_small_islands(&mut tiny, 100));
        assert_eq!(tiny.area(), 6, "all small: the largest is kept");
        // Diagonal neighbours are connected (8-connectivity).
        let mut diagonal = BitMask::new(5, 5);
        diagonal.set(1, 1, true);
        diagonal.set(2, 2, true);
        assert!(!remove_small_islands(&mut diagonal, 2));
    }
}
