//! CLIP: tokenizer, image preprocessing, masked crops, and the image/text encoders.

pub mod encoder;
pub mod masked_crop;
pub mod preprocess;
pub mod text_clean;
pub mod tokenizer;

pub use encoder::{
    ClipImageEncoder, ClipTextEncoder, DEFAULT_BATCH_SIZE, DEFAULT_TEXT_CACHE_ENTRIES, l2_normalise,
};
pub use masked_crop::masked_square_crop;
pub use preprocess::clip_pixel_values;
pub use text_clean::clean_text;
pub use tokenizer::ClipTokenizer;
