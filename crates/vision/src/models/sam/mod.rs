//! Segment-Anything-family models (SAM 1, MobileSAM, SAM 2.1): encoder preprocessing and the
//! prompt driver, which also implements the mask generator's `PointPromptSegmenter` and mask
//! propagation's `RegionPromptSegmenter`.

pub mod batching;
pub mod mask_postprocess;
pub mod mask_probe;
pub mod predictor;
pub mod preprocess;
mod region;

pub use batching::DecoderBatching;
pub use predictor::{
    DEFAULT_PROMPT_CHUNK, EncodedImage, LOW_RES_SIDE, OBJECT_SCORE_OUTPUT, PointLabel, SamAnswer,
    SamModel, SamPredictor, SamPrompt,
};
pub use preprocess::{EncoderInput, longest_side_size, sam_encoder_input};
