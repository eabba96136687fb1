//! The GPU render loss (`0.8 * L1 + 0.2 * (1 - SSIM)`) against an f64 CPU reference written
//! independently (direct 2D window, not separable), whose gradient is itself checked by central
//! finite differences.
//!
//! Tolerances (f32 on the GPU vs f64): loss within 2e-6 relative + 1e-6 absolute (measured: about
//! 3e-7 relative); each gradient value within 1e-4 of the largest gradient magnitude (measured:
//! about 1e-5; the finite-difference check allows 1e-3). A wrong term, sign, window or padding
//! misses these by orders of magnitude.
//!
//! - [`reference`]: the f64 CPU reference and its finite-difference check;
//! - [`render_loss`]: the GPU render loss against it;
//! - [`object_loss`]: the object loss (masked targets, skipped empty cells, batched slots).

#[path = "../gpu_support/mod.rs"]
mod gpu_support;

mod object_loss;
mod reference;
mod render_loss;
