//! Gaussian splatting engine: the scene model, cameras, the CPU reference renderer (ground truth for
//! tests) and the GPU renderer (forward and backward).
//!
//! Rasterisation constants follow 3DGS / gsplat exactly so trained scenes behave like theirs.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

pub mod adam;
pub mod background_shell;
pub mod camera;
pub mod checkpoint;
pub mod deform;
pub mod densify;
pub mod image_metrics;
pub mod init;
pub mod labels;
pub mod loss;
pub mod model;
pub mod ply;
pub mod reference;
pub mod render;
pub mod schedule;
pub mod spz;
pub mod train;

pub use camera::RenderCamera;
pub use model::{GaussianModel, GpuGaussianGrads, GpuGaussians, OBJECT_NONE};

use segsplat_scene::Level;

/// Side of a square screen tile in pixels (one rasterisation workgroup per tile).
pub const TILE_SIZE: u32 = 16;
/// Side of the squares whose occupancy a batch of object renders marks
/// ([`render::ObjectBatchOutput::occupancy`]).
pub const OCCUPANCY_CELL: u32 = 8;
/// Fragments with alpha below this are skipped.
pub const ALPHA_MIN: f32 = 1.0 / 255.0;
/// Per-fragment alpha is clamped to this.
pub const ALPHA_MAX: f32 = 0.99;
/// A pixel stops at the fragment that would take its transmittance to or below this.
pub const TRANSMITTANCE_MIN: f32 = 1.0e-4;
/// Added to the 2D covariance diagonal (pixels^2): the EWA low-pass filter of 3DGS.
pub const COVARIANCE_DILATION: f32 = 0.3;
/// The Jacobian is evaluated with x/z and y/z clamped to this multiple of the half-field tangent.
pub const FRUSTUM_SLACK: f32 = 1.3;
/// Screen radius of a splat in standard deviations of its major axis.
pub const RADIUS_SIGMAS: f32 = 3.0;

/// Which Gaussians a render draws: all, or only those of one object at one level (the others are
/// absent: they neither show nor occlude).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ObjectFilter {
    #[default]
    All,
    Object {
        level: Level,
        id: u32,
    },
}

impl ObjectFilter {
    /// Whether a Gaussian with these ids is drawn.
    pub fn keeps(&self, object_ids: [u32; 3]) -> bool {
        match *self {
            ObjectFilter::All => true,
            ObjectFilter::Object { level, id } => object_ids[level.index()] == id,
        }
    }
}

/// What a render draws, besides the scene and camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    pub filter: ObjectFilter,
    /// Linear RGB composited behind the splats.
    pub background: [f32; 3],
    /// SH degree used for colour (0..=3); coefficients above it are ignored.
    pub sh_degree: u32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            filter: ObjectFilter::All,
            background: [0.0; 3],
            sh_degree: model::MAX_SH_DEGREE,
        }
    }
}
