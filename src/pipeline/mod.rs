//! Job kinds that turn uploaded scenes into trained ones.

pub mod reconstruct;
pub mod segment_then_splat;

pub use reconstruct::ReconstructHandler;
