//! [`SamPredictor`] as a [`RegionPromptSegmenter`], what mask propagation drives.
//!
//! The answer is the decoder's single-mask output (channel 0), not one of the three multimask
//! channels: a box plus points plus a previous mask is an unambiguous prompt, for which SAM's
//! authors recommend the single output, and SAM 2's video predictor follows tracked objects with
//! it too. Its low-resolution logits come back as the next prompt's mask prior, so the prior and
//! the answer stay one channel.

use image::RgbImage;

use super::predictor::{PointLabel, SamPredictor, SamPrompt};
use crate::models::error::ModelError;
use crate::segment::mask::BitMask;
use crate::segment::prompt::{PointPromptSegmenter, PromptError};
use crate::segment::region_prompt::{RegionAnswer, RegionPrompt, RegionPromptSegmenter};

/// The decoder channel answered for region prompts.
const SINGLE_MASK_CHANNEL: usize = 0;

fn model_error(error: impl std::error::Error + Send + Sync + 'static) -> PromptError {
    PromptError::Model(Box::new(error))
}

/// Positive points first: decoders (and the tiny stand-in) read the first point as the object.
fn sam_prompt(prompt: &RegionPrompt) -> SamPrompt {
    let positives = prompt
        .positive_points
        .iter()
        .map(|point| (*point, PointLabel::Foreground));
    let negatives = prompt
        .negative_points
        .iter()
        .map(|point| (*point, PointLabel::Background));
    SamPrompt {
        points: positives.chain(negatives).collect(),
        bounding_box: prompt.bounding_box,
        mask_input: prompt.mask_input.clone(),
    }
}

impl RegionPromptSegmenter for SamPredictor {
    fn set_image(&mut self, image: &RgbImage) -> Result<(), PromptError> {
        PointPromptSegmenter::set_image(self, image)
    }

    fn predict_regions(
        &mut self,
        prompts: &[RegionPrompt],
    ) -> Result<Vec<RegionAnswer>, PromptError> {
        let Some(image) = self.encoded_image() else {
            return Err(PromptError::NoImage);
        };
        let (width, height) = (image.width, image.height);
        let mut answers = Vec::with_capacity(prompts.len());
        // One predictor chunk at a time, so at most a chunk of four-channel full-resolution
        // logit maps is alive before it shrinks to bit masks.
        for chunk in prompts.chunks(self.chunk()) {
            let sam_prompts: Vec<SamPrompt> = chunk.iter().map(sam_prompt).collect();
            for mut answer in self.predict(&sam_prompts).map_err(model_error)? {
                let (Some(logits), Some(&predicted_iou)) = (
                    answer.logits.get(SINGLE_MASK_CHANNEL),
                    answer.predicted_iou.get(SINGLE_MASK_CHANNEL),
                ) else {
                    return Err(model_error(ModelError::Output {
                        model: self.model().decoder_name().to_string(),
                        reason: "no single-mask channel".to_string(),
                    }));
                };
                if !answer.object_present() {
                    // SAM 2's trackers read "no object" as an empty mask, whatever the mask
                    // channels hold: the track counts this frame as lost.
                    answers.push(RegionAnswer {
                        mask: BitMask::new(width, height),
                        predicted_iou: 0.0,
                        low_res_logits: None,
                    });
                    continue;
                }
                let mask = BitMask::from_logits(width, height, logits, 0.0).map_err(model_error)?;
                let low_res_logits = (SINGLE_MASK_CHANNEL < answer.low_res_logits.len())
                    .then(|| answer.low_res_logits.swap_remove(SINGLE_MASK_CHANNEL));
                answers.push(RegionAnswer {
                    mask,
                    predicted_iou,
                    low_res_logits,
                });
            }
        }
        Ok(answers)
    }
}
