//! The service's `scene` module (every parser of client bytes), compiled on its own.
//!
//! The fuzz targets call `scene::fuzz_entry`, the same functions `tests/fuzz_corpus.rs` replays
//! the corpus through. This crate compiles `src/scene` by path instead of depending on the
//! `segsplat` crate because an instrumented nightly build of the whole service (wgpu, ONNX
//! Runtime, tonic, sqlx, ...) takes tens of minutes, while `scene` needs only the few crates
//! listed in Cargo.toml: it refers to nothing else in the service (`tests/fuzz_corpus.rs`
//! checks that it stays so).
#![allow(dead_code, unused_imports, clippy::all)]

#[path = "../../src/scene/mod.rs"]
pub mod scene;
