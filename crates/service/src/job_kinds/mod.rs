//! The job kinds the service runs: `reconstruct` (plain 3DGS) and `segment_then_splat`, each a
//! [`crate::jobs::JobHandler`] that drives the method's stages with checkpoints, progress,
//! cancellation and stored results.

pub mod checkpoint_writer;
pub mod reconstruct;
pub mod segment_then_splat;
pub mod stage_cadence;
pub mod stop_aware;
pub mod trainer_setup;
pub mod training;

pub use reconstruct::ReconstructHandler;
pub use segment_then_splat::SegmentThenSplatHandler;
