//! Job kinds that turn uploaded scenes into trained ones.

pub mod reconstruct;
pub mod segment_then_splat;
pub mod serving;
pub mod training_job;

pub use reconstruct::ReconstructHandler;
pub use segment_then_splat::job::SegmentThenSplatHandler;
