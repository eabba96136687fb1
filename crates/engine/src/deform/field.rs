//! The deformation field's shape and its flat parameter layout.
//!
//! Deformable 3D Gaussians (Yang et al. 2024): `F(gamma(x), gamma(t)) -> (dx, dr, ds)`, an MLP of
//! `depth` ReLU layers of `width`, whose input (the encoded position and time) is concatenated
//! again after layer `skip_after` (1-based, as `skips = [D // 2]` in the released code: the fifth
//! layer of eight reads `[gamma(x), gamma(t), h4]`). One linear head replaces the released code's
//! three (warp, rotation, scaling): stacking their rows is the same function with one GEMM.
//!
//! All weights and biases live in one flat f32 array so one Adam dispatch updates them all. Per
//! layer: the weight matrix `[outputs, inputs]` row-major (PyTorch's `nn.Linear` layout), then the
//! bias `[outputs]`.

use rand::Rng;
use serde::{Deserialize, Serialize};

/// How the head's translation part moves a Gaussian.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum WarpKind {
    /// `x + dx` (the released code's default).
    #[default]
    Translation,
    /// An SE(3) screw motion `exp([w, v])` applied to `x` (the released code's `is_6dof`).
    Screw,
}

impl WarpKind {
    /// Head outputs spent on position: `dx` (3) or the screw's `w` and `v` (6).
    pub fn outputs(self) -> usize {
        match self {
            WarpKind::Translation => 3,
            WarpKind::Screw => 6,
        }
    }
}

/// The field's architecture (docs/method.md "Dynamic scenes": 8 x 256, skip at 4, 10 frequencies).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FieldShape {
    pub depth: u32,
    pub width: u32,
    /// The input is concatenated to the output of this layer (1-based); 0 disables the skip.
    pub skip_after: u32,
    pub position_frequencies: u32,
    pub time_frequencies: u32,
    pub warp: WarpKind,
}

impl Default for FieldShape {
    fn default() -> Self {
        Self {
            depth: 8,
            width: 256,
            skip_after: 4,
            position_frequencies: 10,
            time_frequencies: 10,
            warp: WarpKind::Translation,
        }
    }
}

/// Head outputs after the warp: the quaternion delta (4) and the log-scale delta (3).
pub const ROTATION_AND_SCALE_OUTPUTS: usize = 7;

/// One linear layer's place in the flat parameter array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinearLayer {
    pub inputs: usize,
    pub outputs: usize,
    pub weight_offset: usize,
    pub bias_offset: usize,
    /// ReLU after this layer (every layer but the head).
    pub relu: bool,
}

impl LinearLayer {
    pub fn parameter_count(&self) -> usize {
        self.inputs * self.outputs + self.outputs
    }
}

/// The field a software (CPU) adapter trains when a config leaves the shape out
/// ([`FieldShape::for_adapter`]): 4 layers of 64, the input joining again after layer 2, the
/// released encodings. It is the shape `tests/train_dynamic.rs` trains.
pub const SOFTWARE_FIELD: FieldShape = FieldShape {
    depth: 4,
    width: 64,
    skip_after: 2,
    position_frequencies: 10,
    time_frequencies: 10,
    warp: WarpKind::Translation,
};

impl FieldShape {
    /// The field a config that leaves the shape out trains with: the released 8 x 256 on a
    /// hardware adapter, [`SOFTWARE_FIELD`] on a software one. On lavapipe the field is nearly
    /// all of a dynamic step: with 8 x 256 over the figurine's 2,443 Gaussians a dynamic step
    /// is 23x a static one, and no kernel could bring it under 5.3x; 4 x 64 is 3.1x, and on the
    /// moving spheres it held out as much as 8 x 256 at equal steps (docs/engine.md, "The field
    /// a CPU adapter trains").
    pub fn for_adapter(software: bool) -> Self {
        if software {
            SOFTWARE_FIELD
        } else {
            Self::default()
        }
    }

    /// Rejects shapes the kernels cannot run, naming the field.
    pub fn validate(&self) -> Result<(), String> {
        if self.depth == 0 || self.depth > 16 {
            return Err(format!("depth must be 1..=16, got {}", self.depth));
        }
        if self.width == 0 || self.width > 1024 {
            return Err(format!("width must be 1..=1024, got {}", self.width));
        }
        if self.skip_after >= self.depth {
            return Err(format!(
                "skip_after must be below depth ({}), got {}",
                self.depth, self.skip_after
            ));
        }
        if self.skip_after == 1 {
            // Layer 1 would read the encoding from the skip buffer and write its output into
            // the same buffer in one dispatch, which wgpu forbids (read-write aliasing).
            return Err("skip_after must be 0 (no skip) or at least 2, got 1".into());
        }
        if self.position_frequencies > 16 || self.time_frequencies > 16 {
            return Err("position_frequencies and time_frequencies must be at most 16".into());
        }
        Ok(())
    }

    /// `gamma(x)`: x itself and a sine and cosine per frequency and axis.
    pub fn position_encoding_width(&self) -> usize {
        3 * (1 + 2 * self.position_frequencies as usize)
    }

    pub fn time_encoding_width(&self) -> usize {
        1 + 2 * self.time_frequencies as usize
    }

    /// `[gamma(x), gamma(t)]`.
    pub fn encoding_width(&self) -> usize {
        self.position_encoding_width() + self.time_encoding_width()
    }

    pub fn head_outputs(&self) -> usize {
        self.warp.outputs() + ROTATION_AND_SCALE_OUTPUTS
    }

    /// The layers in order: `depth` hidden layers, then the head.
    pub fn layers(&self) -> Vec<LinearLayer> {
        let width = self.width as usize;
        let encoding = self.encoding_width();
        let mut layers = Vec::with_capacity(self.depth as usize + 1);
        let mut offset = 0;
        let mut push = |inputs: usize, outputs: usize, relu: bool| {
            let layer = LinearLayer {
                inputs,
                outputs,
                weight_offset: offset,
                bias_offset: offset + inputs * outputs,
                relu,
            };
            offset += layer.parameter_count();
            layers.push(layer);
        };
        for index in 1..=self.depth {
            let inputs = if index == 1 {
                encoding
            } else if index == self.skip_after + 1 && self.skip_after > 0 {
                encoding + width
            } else {
                width
            };
            push(inputs, width, true);
        }
        push(width, self.head_outputs(), false);
        layers
    }

    pub fn parameter_count(&self) -> usize {
        self.layers().iter().map(LinearLayer::parameter_count).sum()
    }

    /// Floating-point operations per Gaussian of the GPU passes' matrix products (a
    /// multiply-add counts 2), `(forward, backward)`: the forward's `inputs x outputs` per
    /// layer; the backward's weight gradients (as many) and input gradients of every layer but
    /// the first, over the previous layer's `width` columns only (the encoding gets no
    /// gradient). Biases, the encoding and the warp are left out (under 1% at 8 x 256).
    pub fn flops_per_gaussian(&self) -> (u64, u64) {
        let layers = self.layers();
        let products: u64 = layers.iter().map(|l| (l.inputs * l.outputs) as u64).sum();
        let input_gradients: u64 = layers
            .iter()
            .skip(1)
            .map(|l| (l.outputs * self.width as usize) as u64)
            .sum();
        (2 * products, 2 * (products + input_gradients))
    }

    /// PyTorch's default `nn.Linear` initialisation of every layer (what the released code
    /// trains from): weights and biases uniform in `+-1/sqrt(inputs)`.
    pub fn random_parameters(&self, rng: &mut impl Rng) -> Vec<f32> {
        let mut parameters = vec![0.0f32; self.parameter_count()];
        for layer in self.layers() {
            let bound = 1.0 / (layer.inputs as f32).sqrt();
            let end = layer.bias_offset + layer.outputs;
            for value in &mut parameters[layer.weight_offset..end] {
                *value = rng.random_range(-bound..=bound);
            }
        }
        parameters
    }

    /// The training start: [`Self::random_parameters`] with the head at zero. The released
    /// code's random head moves every Gaussian by a random offset the moment the warm-up ends; a
    /// zero head starts the field as the identity, and its weight gradients (`dZ^T h`) are
    /// non-zero from the first step, so it learns all the same.
    pub fn initial_parameters(&self, rng: &mut impl Rng) -> Vec<f32> {
        let mut parameters = self.random_parameters(rng);
        if let Some(head) = self.layers().last() {
            parameters[head.weight_offset..head.bias_offset + head.outputs].fill(0.0);
        }
        parameters
    }
}

/// `gamma(p)` for one scalar or vector: `[p, sin(2^0 p), cos(2^0 p), ..., sin(2^(L-1) p),
/// cos(2^(L-1) p)]`, each term over all components (the NeRF embedder's order).
pub fn encode_into(values: &[f64], frequencies: u32, out: &mut Vec<f64>) {
    out.extend_from_slice(values);
    for level in 0..frequencies {
        let scale = f64::from(1u32 << level);
        out.extend(values.iter().map(|v| (v * scale).sin()));
        out.extend(values.iter().map(|v| (v * scale).cos()));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_shape_matches_deformable_3dgs() {
        let shape = FieldShape::default();
        assert_eq!(shape.position_encoding_width(), 63);
        assert_eq!(shape.time_encoding_width(), 21);
        let layers = shape.layers();
        assert_eq!(layers.len(), 9);
        assert_eq!(layers[0].inputs, 84);
        assert_eq!(layers[4].inputs, 84 + 256);
        assert_eq!(layers[8].outputs, 10);
        assert!(!layers[8].relu);
        let last = layers[8];
        assert_eq!(shape.parameter_count(), last.bias_offset + last.outputs);
        // 84x256 + 6 x 256x256 + 340x256 + 256x10 multiply-adds forward; the backward adds
        // 7 x 256x256 + 10x256 for the input gradients.
        let forward = 84 * 256 + 6 * 65_536 + 340 * 256 + 2_560;
        let (f, b) = shape.flops_per_gaussian();
        assert_eq!(f, 2 * forward);
        assert_eq!(b, 2 * (forward + 7 * 65_536 + 2_560));
    }

    #[test]
    fn encoding_order_is_the_nerf_embedder() {
        let mut out = Vec::new();
        encode_into(&[0.5, 1.0], 2, &mut out);
        let expected = [
            0.5,
            1.0,
            0.5f64.sin(),
            1.0f64.sin(),
            0.5f64.cos(),
            1.0f64.cos(),
            1.0f64.sin(),
            2.0f64.sin(),
            1.0f64.cos(),
            2.0f64.cos(),
        ];
        assert_eq!(out, expected);
    }

    #[test]
    fn bad_shapes_are_named() {
        let shape = FieldShape {
            skip_after: 8,
            ..FieldShape::default()
        };
        assert!(shape.validate().unwrap_err().contains("skip_after"));
        let aliased = FieldShape {
            skip_after: 1,
            ..FieldShape::default()
        };
        assert!(aliased.validate().unwrap_err().contains("skip_after"));
    }
}
