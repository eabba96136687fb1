//! The seam between mask propagation and the model that answers region prompts (box, points and
//! a previous mask) with one mask each: a Segment-Anything-family decoder in `models::sam`, or a
//! stand-in in tests.

use super::mask::BitMask;
use super::prompt::PromptError;

/// One region prompt, in pixels of the image given to
/// [`set_image`](RegionPromptSegmenter::set_image).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RegionPrompt {
    /// `[x0, y0, x1, y1]`, pixel edges (a box around pixel columns 3..=5 is `x0 = 3, x1 = 6`).
    pub bounding_box: Option<[f32; 4]>,
    /// Points on the object, `[x, y]`.
    pub positive_points: Vec<[f32; 2]>,
    /// Points off the object.
    pub negative_points: Vec<[f32; 2]>,
    /// A previous answer's [`RegionAnswer::low_res_logits`] from the same segmenter, as a prior.
    /// Its layout is the segmenter's own; callers only hand it back.
    pub mask_input: Option<Vec<f32>>,
}

/// The answer to one [`RegionPrompt`].
#[derive(Debug, Clone, PartialEq)]
pub struct RegionAnswer {
    /// The object, at the full resolution of the image (empty when the model found nothing).
    pub mask: BitMask,
    /// The model's own estimate of the mask's IoU with the object (0..=1).
    pub predicted_iou: f32,
    /// What to feed back as [`RegionPrompt::mask_input`] when prompting for this object again;
    /// `None` when the segmenter takes no mask prior.
    pub low_res_logits: Option<Vec<f32>>,
}

/// A model that segments one image from region prompts. The image is encoded once by
/// [`set_image`](RegionPromptSegmenter::set_image); prompts then run against that encoding.
pub trait RegionPromptSegmenter {
    /// Encodes `image` (RGB8). Later prompts refer to this image until the next call.
    fn set_image(&mut self, image: &image::RgbImage) -> Result<(), PromptError>;

    /// One answer per prompt, in order. Callers bound `prompts.len()` to keep memory in check.
    fn predict_regions(
        &mut self,
        prompts: &[RegionPrompt],
    ) -> Result<Vec<RegionAnswer>, PromptError>;
}
