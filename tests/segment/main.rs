//! Mask generation from outside, a module per generator:
//!
//! - [`classical`]: the classical fallback segmenter on flat synthetic shapes;
//! - [`automatic`]: automatic masks with a stand-in prompt model on nested discs at three sizes;
//! - [`user`]: user-provided instance masks, with the scene loader's level fallback;
//! - [`propagation`]: masks tracked from frame to frame through the tiny ONNX SAM stand-in.

#[path = "../models_support/mod.rs"]
mod models_support;

mod automatic;
mod classical;
mod propagation;
mod user;
