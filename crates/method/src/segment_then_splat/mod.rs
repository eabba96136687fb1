//! The Segment-then-Splat pipeline (docs/method.md): masks per view at three levels, object ids on the
//! initial points, training with the object loss, per-object language embeddings.

pub mod association;
/// The background shell lives with the trainer (plain training uses it too).
pub use segsplat_engine::background_shell;
pub mod carved_hulls;
pub mod frame_masks;
mod global_objects;
pub mod hull_points;
pub mod id_voting;
mod mask_links;
pub mod objects;
mod projected_visibility;
pub mod propagated_masks;
pub mod scene_size;
pub mod track_merge;
pub mod track_metrics;
pub mod training;
pub mod view_masks;
