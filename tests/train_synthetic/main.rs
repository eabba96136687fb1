//! Training on a synthetic scene with known ground truth: three shaded spheres seen by 32
//! cameras on a ring (the scene module's synthetic COLMAP dataset). Held-out PSNR after a short
//! training must clear a bar that a broken gradient cannot reach, and checkpoints must restore
//! the trainer's state exactly.
//!
//! - [`training`]: what a short run reaches, its schedule, budget and steady steps, the
//!   convergence stop, and the training views loaded alike on one thread and on several;
//! - [`checkpoints`]: a checkpoint restores the trainer exactly, and its snapshot form is the
//!   blocking one;
//! - [`bench`]: `segsplat bench` from a trained PLY and with the object loss;
//! - [`support`]: the scene and the config they train.

#[path = "../gpu_support/mod.rs"]
mod gpu_support;

mod bench;
mod checkpoints;
mod support;
mod training;
