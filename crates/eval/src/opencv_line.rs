//! OpenCV's 8-connected line (`cv::LineIterator` after `cv::clipLine`), which `fillPoly` draws
//! along every polygon edge before filling. Reproduced step for step, because which pixel a
//! Bresenham tie or a clipped end lands on decides ground-truth border pixels.

use segsplat_vision::segment::mask::BitMask;

pub(crate) type Point = (i64, i64);

/// Draws the line from `start` to `end`, both ends included, clipped to the mask.
pub(crate) fn draw_line(mask: &mut BitMask, start: Point, end: Point) {
    let (mut start, mut end) = (start, end);
    if !clip_line(mask.width(), mask.height(), &mut start, &mut end) {
        return;
    }
    // OpenCV walks from the left end, so ties fall the same way whichever order the edge has.
    let ((x0, y0), (x1, y1)) = if end.0 < start.0 {
        (end, start)
    } else {
        (start, end)
    };
    let (dx, dy) = (x1 - x0, (y1 - y0).abs());
    let y_step = if y1 < y0 { -1 } else { 1 };
    let (major, minor) = (dx.max(dy), dx.min(dy));
    let steep = dy > dx;
    let mut err = major - 2 * minor;
    let (mut x, mut y) = (x0, y0);
    for _ in 0..=major {
        // Both ends were clipped into the image, so every pixel of the walk is inside it.
        mask.set(x as u32, y as u32, true);
        let minor_step = err < 0;
        err += -2 * minor + if minor_step { 2 * major } else { 0 };
        if steep {
            y += y_step;
            x += i64::from(minor_step);
        } else {
            x += 1;
            y += if minor_step { y_step } else { 0 };
        }
    }
}

/// `cv::clipLine` on a `width x height` image: moves `start` and `end` onto the image border
/// with OpenCV's truncating arithmetic, and says whether any of the segment is inside. Like
/// OpenCV it may have moved the points even when it returns `false`; `fillPoly` uses the moved
/// points to slope its edges, so callers get them.
pub(crate) fn clip_line(width: u32, height: u32, start: &mut Point, end: &mut Point) -> bool {
    if width == 0 || height == 0 {
        return false;
    }
    let (right, bottom) = (i64::from(width) - 1, i64::from(height) - 1);
    let ((x1, y1), (x2, y2)) = (start, end);
    let horizontal_code = |x: i64| i32::from(x < 0) + i32::from(x > right) * 2;
    let code =
        |x: i64, y: i64| horizontal_code(x) + i32::from(y < 0) * 4 + i32::from(y > bottom) * 8;
    let (mut c1, mut c2) = (code(*x1, *y1), code(*x2, *y2));
    // `p += (int64)((double)(a - q) * (r - s) / (t - u))`, as OpenCV writes each step.
    let shift = |a: i64, q: i64, r: i64, s: i64, t: i64, u: i64| {
        ((a - q) as f64 * (r - s) as f64 / (t - u) as f64) as i64
    };
    if c1 & c2 == 0 && c1 | c2 != 0 {
        if c1 & 12 != 0 {
            let a = if c1 < 8 { 0 } else { bottom };
            *x1 += shift(a, *y1, *x2, *x1, *y2, *y1);
            *y1 = a;
            c1 = horizontal_code(*x1);
        }
        if c2 & 12 != 0 {
            let a = if c2 < 8 { 0 } else { bottom };
            *x2 += shift(a, *y2, *x2, *x1, *y2, *y1);
            *y2 = a;
            c2 = horizontal_code(*x2);
        }
        if c1 & c2 == 0 && c1 | c2 != 0 {
            if c1 != 0 {
                let a = if c1 == 1 { 0 } else { right };
                *y1 += shift(a, *x1, *y2, *y1, *x2, *x1);
                *x1 = a;
                c1 = 0;
            }
            if c2 != 0 {
                let a = if c2 == 1 { 0 } else { right };
                *y2 += shift(a, *x2, *y2, *y1, *x2, *x1);
                *x2 = a;
                c2 = 0;
            }
        }
    }
    c1 | c2 == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pixels(mask: &BitMask) -> Vec<(u32, u32)> {
        (0..mask.height())
            .flat_map(|y| (0..mask.width()).map(move |x| (x, y)))
            .filter(|&(x, y)| mask.get(x, y))
            .collect()
    }

    #[test]
    fn ties_fall_towards_the_left_end_whichever_way_the_line_is_drawn() {
        // Slope 1/2: at x = 1 the line is at y = 0.5 exactly; OpenCV keeps y = 0 there.
        let mut forward = BitMask::new(5, 3);
        draw_line(&mut forward, (0, 0), (4, 2));
        assert_eq!(pixels(&forward), [(0, 0), (1, 0), (2, 1), (3, 1), (4, 2)]);
        let mut backward = BitMask::new(5, 3);
        draw_line(&mut backward, (4, 2), (0, 0));
        assert_eq!(backward, forward);
    }

    #[test]
    fn steep_and_clipped_lines_stay_in_the_image() {
        let mut steep = BitMask::new(3, 5);
        draw_line(&mut steep, (2, 0), (0, 4));
        assert_eq!(steep.area(), 5);
        assert!(steep.get(2, 0) && steep.get(0, 4));
        let mut clipped = BitMask::new(4, 4);
        draw_line(&mut clipped, (-10, 1), (100, 1));
        assert_eq!(pixels(&clipped), [(0, 1), (1, 1), (2, 1), (3, 1)]);
        let mut outside = BitMask::new(4, 4);
        draw_line(&mut outside, (-10, -1), (100, -1));
        assert!(outside.is_empty());
    }
}
