//! What segsplat sees with: 2D segmenters (automatic, classical, user masks, propagation), the
//! ONNX models behind them (SAM, CLIP) and the language side (text queries, object embeddings).
//! Knows nothing of Gaussians, jobs or HTTP.

pub mod language;
pub mod models;
pub mod segment;
