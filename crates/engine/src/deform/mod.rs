//! Dynamic scenes: the Deformable-3DGS deformation field `F(gamma(x), gamma(t)) -> (dx, dr, ds)`
//! that moves canonical Gaussians to time `t`, trained jointly with them.
//!
//! - [`field`]: architecture and flat parameter layout;
//! - [`warp`]: how the outputs move a Gaussian (translation or SE(3) screw), f64 reference;
//! - [`reference`]: the MLP in f64 (ground truth of the kernels, finite-difference checked);
//! - [`field_gpu`]: the WGSL forward / backward in chunks, Adam on the weights;
//! - [`geometry`]: the deformed buffers a render reads;
//! - [`matmul_bench`]: the adapter's fp32 rate with the field's GEMM kernel.
//!
//! Object ids, opacity and colour stay on the canonical Gaussians, so the object filter and the
//! object loss work unchanged at every time step.

pub mod config;
pub mod field;
pub mod field_gpu;
pub mod file;
mod gemm_broadcast;
pub mod geometry;
mod kernels;
pub mod matmul_bench;
pub mod reference;
pub mod warp;

pub use config::DeformationConfig;
pub use field::{FieldShape, WarpKind};
pub use field_gpu::{DeformError, DeformationField};
pub use file::{DEFORMATION_FILE, DEFORMATION_WEIGHTS_FILE, DeformationHeader, StoredDeformation};
pub use geometry::DeformedGeometry;
pub(crate) use kernels::DeformKernels;
pub use kernels::GemmKernel;
pub use matmul_bench::{MatmulReport, measure_matmul};
