//! language: per-object CLIP embeddings, query scoring with granularity and the calibrated
//! "no match", and the service's shared text encoder. See docs/method.md, stage 4.

pub mod embedding;
pub mod query;
pub mod text_encoder;

pub use embedding::{
    CropEmbedder, EmbeddingAccumulator, EmbeddingError, ObjectVector, ObjectView, object_embeddings,
};
pub use query::{
    CANONICAL_PHRASES, CandidateObject, DEFAULT_RELEVANCY_THRESHOLD, EmbeddingWidthMismatch,
    Granularity, QueryAnswer, QueryOptions, QueryOptionsError, ScoredObject, answer_query,
};
pub use text_encoder::{SharedTextEncoder, TextEncoderUnavailable, image_model_id};
