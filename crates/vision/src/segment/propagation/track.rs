//! One tracked object of one level: its last good mask, how it is prompted on the next frame and
//! whether an answer is taken.

use super::PropagationOptions;
use super::interior::interior_points;
use crate::segment::{BitMask, BoundingBox, RegionAnswer, RegionPrompt};

#[derive(Debug, Clone)]
pub(super) struct Track {
    pub id: u32,
    /// Level index (small, middle, large).
    pub level: usize,
    /// The last accepted mask, whole (before overlaps with other objects were resolved): what the
    /// next prompt is built from and what duplicates are measured on.
    pub mask: BitMask,
    pub area: u64,
    pub bbox: BoundingBox,
    pub predicted_iou: f32,
    /// The segmenter's low-resolution logits of the last accepted answer, the next prior.
    pub prior: Option<Vec<f32>>,
    /// Consecutive frames without an accepted answer; 0 when this frame's answer was taken.
    pub lost_for: usize,
}

/// What became of a track after its answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Outcome {
    Accepted,
    Lost,
    /// Lost for more than `max_lost_frames`: the track ends.
    Ended,
}

impl Track {
    /// A track from a mask known good (frame 0, or a new-object candidate); `None` when empty.
    pub fn new(id: u32, level: usize, mask: BitMask, predicted_iou: f32) -> Option<Track> {
        let bbox = mask.bounding_box()?;
        Some(Track {
            id,
            level,
            area: mask.area(),
            mask,
            bbox,
            predicted_iou,
            prior: None,
            lost_for: 0,
        })
    }

    /// The prompt for the next frame; the prior moves into it (see [`Track::answer`]).
    pub fn prompt(&mut self, options: &PropagationOptions) -> RegionPrompt {
        let (width, height) = (self.mask.width() as f32, self.mask.height() as f32);
        let margin_x = options.box_margin * self.bbox.width() as f32;
        let margin_y = options.box_margin * self.bbox.height() as f32;
        RegionPrompt {
            bounding_box: Some([
                (self.bbox.x_min as f32 - margin_x).max(0.0),
                (self.bbox.y_min as f32 - margin_y).max(0.0),
                (self.bbox.x_max as f32 + 1.0 + margin_x).min(width),
                (self.bbox.y_max as f32 + 1.0 + margin_y).min(height),
            ]),
            positive_points: interior_points(&self.mask, &self.bbox, options.positive_points),
            negative_points: Vec::new(),
            mask_input: self.prior.take(),
        }
    }

    /// Takes `answer` to `prompt` (this track's), or counts the frame as lost and keeps the last
    /// good mask and prior for the next try.
    pub fn answer(
        &mut self,
        prompt: RegionPrompt,
        answer: RegionAnswer,
        options: &PropagationOptions,
    ) -> Outcome {
        let area = answer.mask.area();
        let acceptable = area > 0
            && answer.predicted_iou >= options.min_predicted_iou
            && area as f64 <= options.max_area_growth * self.area as f64;
        let bbox = answer.mask.bounding_box();
        match bbox.filter(|_| acceptable) {
            Some(bbox) => {
                self.mask = answer.mask;
                self.area = area;
                self.bbox = bbox;
                self.predicted_iou = answer.predicted_iou;
                self.prior = answer.low_res_logits;
                self.lost_for = 0;
                Outcome::Accepted
            }
            None => {
                self.prior = prompt.mask_input;
                self.lost_for += 1;
                if self.lost_for > options.max_lost_frames {
                    Outcome::Ended
                } else {
                    Outcome::Lost
                }
            }
        }
    }

    /// Whether this frame's answer was taken (the track shows in this frame).
    pub fn is_seen(&self) -> bool {
        self.lost_for == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x0: u32, y0: u32, side: u32) -> BitMask {
        let mut mask = BitMask::new(64, 48);
        for y in y0..y0 + side {
            mask.set_row_span(y, x0..x0 + side, true);
        }
        mask
    }

    fn answer(mask: BitMask, predicted_iou: f32) -> RegionAnswer {
        RegionAnswer {
            mask,
            predicted_iou,
            low_res_logits: Some(vec![1.0; 4]),
        }
    }

    #[test]
    fn the_prompt_box_grows_by_the_margin_and_stays_in_the_image() {
        let options = PropagationOptions::default();
        let mut track = Track::new(1, 0, square(0, 10, 20), 1.0).expect("non-empty");
        let prompt = track.prompt(&options);
        assert_eq!(prompt.bounding_box, Some([0.0, 8.0, 22.0, 32.0]));
        assert_eq!(prompt.positive_points.len(), options.positive_points);
        assert!(prompt.mask_input.is_none());
    }

    #[test]
    fn bad_answers_lose_the_frame_keep_the_prior_and_end_the_track() {
        let options = PropagationOptions {
            max_lost_frames: 2,
            ..PropagationOptions::default()
        };
        let mut track = Track::new(1, 0, square(10, 10, 10), 1.0).expect("non-empty");
        let prompt = track.prompt(&options);
        assert_eq!(
            track.answer(prompt, answer(square(11, 10, 10), 0.9), &options),
            Outcome::Accepted
        );
        assert_eq!(track.bbox.x_min, 11);
        assert!(track.prior.is_some());
        let bad = [
            answer(BitMask::new(64, 48), 0.9),
            answer(square(11, 10, 10), 0.2),
            answer(square(0, 0, 30), 0.99),
        ];
        let expected = [Outcome::Lost, Outcome::Lost, Outcome::Ended];
        for (bad, expected) in bad.into_iter().zip(expected) {
            let prompt = track.prompt(&options);
            assert!(prompt.mask_input.is_some(), "the last good prior is kept");
            assert_eq!(track.answer(prompt, bad, &options), expected);
            assert_eq!(track.bbox.x_min, 11, "the last good mask is kept");
        }
    }
}
