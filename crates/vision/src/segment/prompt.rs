//! The seam between automatic mask generation and the model that answers point prompts (a
//! Segment-Anything-family decoder in `models::sam`, or a stand-in in tests).

/// The three multimask answers to one positive point prompt, at full image resolution.
#[derive(Debug, Clone)]
pub struct PointMasks {
    /// Mask logits for small, middle, large (decoder channels 1, 2, 3), row-major `height x width`;
    /// a pixel belongs to the mask where its logit is > 0.
    pub logits: [Vec<f32>; 3],
    /// The decoder's predicted IoU of each of the three masks.
    pub predicted_iou: [f32; 3],
    /// False when the model says the point hit no object (SAM 2's object score); the mask
    /// generator then keeps none of the three masks, whatever their predicted IoU.
    pub object_present: bool,
}

/// A model that segments one image from point prompts. The image is encoded once by
/// [`set_image`](PointPromptSegmenter::set_image); prompts then run against that encoding.
pub trait PointPromptSegmenter {
    /// Encodes `image` (RGB8). Later prompts refer to this image until the next call.
    fn set_image(&mut self, image: &image::RgbImage) -> Result<(), PromptError>;

    /// Answers one positive point per entry (`[x, y]` in pixels of the image given to
    /// `set_image`), in order. Callers bound `points.len()` to keep memory in check.
    fn predict_points(&mut self, points: &[[f32; 2]]) -> Result<Vec<PointMasks>, PromptError>;
}

/// Why a prompt model could not answer.
#[derive(Debug, thiserror::Error)]
pub enum PromptError {
    #[error("no image has been set before prompting")]
    NoImage,
    #[error("prompt model failed: {0}")]
    Model(#[source] Box<dyn std::error::Error + Send + Sync>),
}
