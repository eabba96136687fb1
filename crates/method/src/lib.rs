//! Segment then Splat and plain reconstruction as plain functions: masks per view, object ids on
//! the initial points, training with the object loss, object summaries, and the files a trained
//! scene is stored as. No jobs, no store, no HTTP: the service crate drives these stages.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

pub mod cameras;
pub mod scene_files;
pub mod segment_then_splat;
