//! The Segment-then-Splat pipeline (METHOD.md): masks per view at three levels, object ids on the
//! initial points, training with the object loss, per-object language embeddings.

pub mod id_voting;
pub mod objects;
pub mod training;
pub mod view_masks;
pub mod job;
