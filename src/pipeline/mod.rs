//! Job kinds that turn uploaded scenes into trained ones.

pub mod reconstruct;

pub use reconstruct::ReconstructHandler;
