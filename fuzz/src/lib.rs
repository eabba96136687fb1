//! The fuzz targets' one dependency: the `segsplat-scene` crate (every parser of client bytes).
//!
//! The targets call `scene::fuzz_entry`, the same functions `tests/fuzz_corpus.rs` replays the
//! corpus through. Only the scene crate is built, instrumented, because an instrumented nightly
//! build of the whole service (wgpu, ONNX Runtime, tonic, sqlx, ...) takes tens of minutes; the
//! workspace's dependency graph guarantees the scene crate needs nothing else of the service.

pub use segsplat_scene as scene;
