//! Segment then Splat and plain reconstruction as plain functions: masks per view, object ids on
//! the initial points, training with the object loss, object summaries, and the files a trained
//! scene is stored as. No jobs, no store, no HTTP: the service crate drives these stages.

pub mod cameras;
pub mod scene_files;
pub mod segment_then_splat;
