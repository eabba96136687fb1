//! CPU reference renderer in f64: the ground truth the GPU kernels are tested against, and the
//! gradients the finite-difference tests check. Plain loops, no tiles or sorting tricks: every
//! pixel walks all Gaussians in depth order and takes every fragment whose alpha reaches 1/255, so
//! the GPU matches it only if its tile lists hold every such fragment.
//!
//! Semantics (shared with the GPU; constants in [`segsplat_engine`]): EWA projection with the 3DGS
//! frustum clamp and 0.3 px^2 dilation, front-to-back compositing with
//! `alpha = min(0.99, o * exp(-sigma))`, fragments with `alpha < 1/255` (or `sigma < 0`) skipped,
//! and a pixel stops before the fragment that would take its transmittance to `<= 1e-4`.

pub mod project;
pub mod rasterize;
pub mod scenes;
pub mod sh;

use glam::{DMat3, DVec3};

use crate::model::SH_COEFFICIENTS;
use crate::{GaussianModel, RenderCamera, RenderSettings};

pub use project::{ProjectedGaussian, project_gaussian};
pub use rasterize::{ReferenceForward, render_backward, render_forward};

/// A Gaussian scene in f64 (finite differences need more precision than f32 gives).
/// Also the shape of reference gradients.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReferenceGaussians {
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub rotations: Vec<[f64; 4]>,
    pub opacity_logits: Vec<f64>,
    pub sh_coefficients: Vec<[[f64; 3]; SH_COEFFICIENTS]>,
    pub object_ids: Vec<[u32; 3]>,
}

impl ReferenceGaussians {
    pub fn from_model(model: &GaussianModel) -> Self {
        let widen3 = |v: &[f32; 3]| v.map(f64::from);
        Self {
            means: model.means.iter().map(widen3).collect(),
            log_scales: model.log_scales.iter().map(widen3).collect(),
            rotations: model.rotations.iter().map(|q| q.map(f64::from)).collect(),
            opacity_logits: model.opacity_logits.iter().map(|&o| o as f64).collect(),
            sh_coefficients: model
                .sh_coefficients
                .iter()
                .map(|sh| sh.map(|rgb| rgb.map(f64::from)))
                .collect(),
            object_ids: model.object_ids.clone(),
        }
    }

    /// Zeroed gradients for `count` Gaussians.
    pub fn zeros(count: usize) -> Self {
        Self {
            means: vec![[0.0; 3]; count],
            log_scales: vec![[0.0; 3]; count],
            rotations: vec![[0.0; 4]; count],
            opacity_logits: vec![0.0; count],
            sh_coefficients: vec![[[0.0; 3]; SH_COEFFICIENTS]; count],
            object_ids: Vec::new(),
        }
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Every scalar parameter of Gaussian `index`, in a fixed order (means, log_scales,
    /// rotations, opacity logit, SH coefficient-major): for finite differences and comparisons.
    pub fn parameters_mut(&mut self, index: usize) -> Vec<&mut f64> {
        let mut out: Vec<&mut f64> = Vec::with_capacity(59);
        out.extend(self.means[index].iter_mut());
        out.extend(self.log_scales[index].iter_mut());
        out.extend(self.rotations[index].iter_mut());
        out.push(&mut self.opacity_logits[index]);
        out.extend(self.sh_coefficients[index].iter_mut().flatten());
        out
    }

    /// Read-only counterpart of [`ReferenceGaussians::parameters_mut`].
    pub fn parameters(&self, index: usize) -> Vec<f64> {
        let mut out = Vec::with_capacity(59);
        out.extend_from_slice(&self.means[index]);
        out.extend_from_slice(&self.log_scales[index]);
        out.extend_from_slice(&self.rotations[index]);
        out.push(self.opacity_logits[index]);
        out.extend(self.sh_coefficients[index].iter().flatten());
        out
    }
}

/// Names of the scalars [`ReferenceGaussians::parameters`] lists, for test messages.
pub fn parameter_name(slot: usize) -> String {
    match slot {
        0..=2 => format!("mean[{slot}]"),
        3..=5 => format!("log_scale[{}]", slot - 3),
        6..=9 => format!("rotation[{}]", slot - 6),
        10 => "opacity_logit".to_string(),
        _ => format!("sh[{}][{}]", (slot - 11) / 3, (slot - 11) % 3),
    }
}

/// Reference gradients: parameters plus the absolute screen-space mean gradient sum.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReferenceGrads {
    pub parameters: ReferenceGaussians,
    /// Per Gaussian, sum over pixels of |dL/d mean2d| per axis (pixels).
    pub mean2d_abs: Vec<[f64; 2]>,
}

/// The camera in f64.
#[derive(Debug, Clone, Copy)]
pub struct ReferenceCamera {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub rotation: DMat3,
    pub translation: DVec3,
    pub position: DVec3,
    pub near: f64,
    pub far: f64,
    /// Where the Jacobian clamps x/z and y/z ([`RenderCamera::jacobian_limit`]).
    pub jacobian_limit: [f64; 2],
}

impl ReferenceCamera {
    pub fn new(camera: &RenderCamera) -> Self {
        let m = camera.camera_from_world.as_dmat4();
        let rotation = DMat3::from_mat4(m);
        let translation = m.w_axis.truncate();
        Self {
            width: camera.width,
            height: camera.height,
            fx: camera.fx as f64,
            fy: camera.fy as f64,
            cx: camera.cx as f64,
            cy: camera.cy as f64,
            rotation,
            translation,
            position: m.inverse().w_axis.truncate(),
            near: camera.near as f64,
            far: camera.far as f64,
            jacobian_limit: camera.jacobian_limit().map(f64::from),
        }
    }

    pub fn tiles(&self) -> [u32; 2] {
        [
            self.width.div_ceil(crate::TILE_SIZE),
            self.height.div_ceil(crate::TILE_SIZE),
        ]
    }
}

/// Settings in the reference's terms.
pub type ReferenceSettings = RenderSettings;
