//! What segsplat sees with: 2D segmenters (automatic, classical, user masks, propagation), the
//! ONNX models behind them (SAM, CLIP) and the language side (text queries, object embeddings).
//! Knows nothing of Gaussians, jobs or HTTP.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

pub mod language;
pub mod models;
pub mod segment;
