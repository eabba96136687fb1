//! The model layer from outside, on the tiny stand-in models (tests/fixtures/models/tiny) and the
//! official exporters' signatures (tests/fixtures/models/official), a module per concern:
//!
//! - [`runtime`]: ONNX Runtime is found and loaded, and a missing or wrong library is a clear
//!   error rather than a panic;
//! - [`store`]: the model store's load-time checks, each problem with its own precise error;
//! - [`official`]: folders of ONNX files as users bring them, turned into model directories by
//!   `models init`;
//! - [`sam`]: the SAM driver's point prompts;
//! - [`clip`]: the CLIP tokenizer and preprocessing against open_clip's, and the encoders end to
//!   end.

#[path = "../models_support/mod.rs"]
mod models_support;

mod clip;
mod official;
mod runtime;
mod sam;
mod store;
