//! The training job kinds end to end through the service on the GPU worker (lavapipe in CI):
//! upload, submit, progress over the job record, artifacts in the blob store, objects in the
//! database.
//!
//! - [`reconstruct`]: plain training jobs;
//! - [`objects`]: `segment_then_splat` jobs and the objects they store;
//! - [`queries`]: a trained scene asked in words;
//! - [`support`]: what they share.

#[path = "../common/mod.rs"]
mod common;

mod objects;
mod queries;
mod reconstruct;
mod support;
