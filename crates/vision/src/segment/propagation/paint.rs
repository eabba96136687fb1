//! One pixel, one object per level: the accepted masks of a level become an id image.
//!
//! Where masks overlap, the smaller mask wins, as `instance_ids_from_masks` decides for a single
//! frame's masks: a small object sitting on a larger one (a cup on a table) would otherwise
//! vanish under it, and a mask that bled into its neighbour is the larger of the two. Equal areas
//! go to the higher predicted IoU, then to the older (lower) id, so the outcome does not depend on
//! the order tracks are kept in.

use super::track::Track;

/// The id image of `level` from the tracks seen in this frame.
pub(super) fn paint_level(tracks: &[Track], level: usize, width: u32, height: u32) -> Vec<u32> {
    let mut ids = vec![0u32; width as usize * height as usize];
    let mut order: Vec<&Track> = tracks
        .iter()
        .filter(|track| track.level == level && track.is_seen())
        .collect();
    // Painted in reverse order of precedence: the last painted wins.
    order.sort_by(|a, b| {
        b.area
            .cmp(&a.area)
            .then(a.predicted_iou.total_cmp(&b.predicted_iou))
            .then(b.id.cmp(&a.id))
    });
    for track in order {
        for y in track.bbox.y_min..=track.bbox.y_max {
            let row = y as usize * width as usize;
            for x in track.mask.row_set_columns(y) {
                ids[row + x as usize] = track.id;
            }
        }
    }
    ids
}

/// Share of pixels without an object.
pub(super) fn uncovered_share(ids: &[u32]) -> f64 {
    if ids.is_empty() {
        return 0.0;
    }
    ids.iter().filter(|&&id| id == 0).count() as f64 / ids.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment::BitMask;

    fn track(id: u32, x0: u32, side: u32, predicted_iou: f32) -> Track {
        let mut mask = BitMask::new(20, 10);
        for y in 0..side {
            mask.set_row_span(y, x0..x0 + side, true);
        }
        Track::new(id, 0, mask, predicted_iou).expect("non-empty")
    }

    #[test]
    fn smaller_then_surer_then_older_wins() {
        let tracks = [
            track(1, 0, 8, 0.9),
            track(2, 2, 4, 0.5),
            track(3, 10, 5, 0.7),
            track(4, 11, 5, 0.8),
            track(6, 16, 4, 0.8),
            track(5, 16, 4, 0.8),
        ];
        let ids = paint_level(&tracks, 0, 20, 10);
        assert_eq!(ids[3], 2, "the small square inside the large one");
        assert_eq!(ids[0], 1);
        assert_eq!(ids[12], 4, "equal areas: the higher predicted IoU");
        assert_eq!(ids[10], 3);
        assert_eq!(ids[18], 5, "all equal: the older id");
        assert_eq!(ids[9 * 20], 0);
        assert!((uncovered_share(&ids) - (200.0 - 64.0 - 30.0 - 16.0) / 200.0).abs() < 1e-9);
        assert!(paint_level(&tracks, 1, 20, 10).iter().all(|&id| id == 0));
    }
}
