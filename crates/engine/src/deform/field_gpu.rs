//! The deformation field on the GPU: parameters, gradients and Adam moments in flat buffers, and
//! the forward / backward passes over the Gaussians in chunks.
//!
//! Activations are kept for one chunk of Gaussians at a time (`max_chunk_rows`), so memory stays
//! bounded whatever the scene size: the backward pass recomputes a chunk's activations when the
//! scene needed more than one (gradient checkpointing); with one chunk it reuses the forward's.

use crate::adam::{Adam, AdamBuffers, AdamError};
use crate::{GpuGaussianGrads, GpuGaussians};
use segsplat_gpu::{GpuContext, GpuError};

use super::field::{FieldShape, LinearLayer, WarpKind};
use super::geometry::DeformedGeometry;
use super::kernels::{
    ApplyParams, DeformKernels, EncodeParams, FLAG_BIAS, FLAG_MASK, FLAG_RELU, GemmBuffers,
    GemmKernel, GemmParams, GemmProduct, MAX_SPLITS,
};

#[derive(Debug, thiserror::Error)]
pub enum DeformError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Adam(#[from] AdamError),
    #[error("deformation field shape: {0}")]
    Shape(String),
    #[error("deformation field has {expected} parameters, got {actual}")]
    ParameterCount { expected: usize, actual: usize },
    #[error("deformed geometry holds {capacity} Gaussians, the scene has {count}")]
    GeometryTooSmall { count: usize, capacity: usize },
}

/// Where a layer's input or output lives in the chunk workspace.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Storage {
    /// `[encoded | output of the skip layer]`.
    Skip,
    Hidden(usize),
    Head,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Slice {
    storage: Storage,
    column: u32,
    row_stride: u32,
}

/// Activation buffers for `rows` Gaussians.
#[derive(Debug)]
struct Workspace {
    rows: usize,
    skip: wgpu::Buffer,
    hidden: Vec<wgpu::Buffer>,
    head: wgpu::Buffer,
    grad_ping: wgpu::Buffer,
    grad_pong: wgpu::Buffer,
    grad_head: wgpu::Buffer,
    partials: wgpu::Buffer,
}

fn storage_buffer(ctx: &GpuContext, label: &str, words: usize) -> Result<wgpu::Buffer, GpuError> {
    ctx.storage_buffer(label, words as u64 * 4)
}

/// The trainable field with its optimiser state.
#[derive(Debug)]
pub struct DeformationField {
    shape: FieldShape,
    layers: Vec<LinearLayer>,
    gemm: GemmKernel,
    kernels: DeformKernels,
    pub parameters: wgpu::Buffer,
    pub grads: wgpu::Buffer,
    pub first_moment: wgpu::Buffer,
    pub second_moment: wgpu::Buffer,
    workspace: Option<Workspace>,
    max_chunk_rows: usize,
    /// First Gaussian of the chunk whose activations the workspace holds (in recorded order).
    resident_chunk: Option<usize>,
}

impl DeformationField {
    /// A field with the given parameters (see [`FieldShape::initial_parameters`]) and zero Adam
    /// moments. `max_chunk_rows` bounds the Gaussians whose activations are held at once.
    pub fn new(
        ctx: &GpuContext,
        shape: FieldShape,
        parameters: &[f32],
        max_chunk_rows: usize,
    ) -> Result<Self, DeformError> {
        let gemm = GemmKernel::for_adapter(ctx);
        Self::with_gemm(ctx, shape, parameters, max_chunk_rows, gemm)
    }

    /// [`Self::new`] with a chosen GEMM kernel rather than the adapter's (tests check both).
    pub fn with_gemm(
        ctx: &GpuContext,
        shape: FieldShape,
        parameters: &[f32],
        max_chunk_rows: usize,
        gemm: GemmKernel,
    ) -> Result<Self, DeformError> {
        shape.validate().map_err(DeformError::Shape)?;
        let expected = shape.parameter_count();
        if parameters.len() != expected {
            return Err(DeformError::ParameterCount {
                expected,
                actual: parameters.len(),
            });
        }
        // The widest activation row must fit one binding for a whole chunk.
        let widest = (shape.encoding_width() + shape.width as usize) * 4;
        let binding_rows = (ctx.limits.max_storage_buffer_binding_size as usize / widest).max(1);
        let field = Self {
            layers: shape.layers(),
            gemm,
            kernels: DeformKernels::with_gemm(ctx, gemm)?,
            parameters: storage_buffer(ctx, "deform.parameters", expected)?,
            grads: storage_buffer(ctx, "deform.grads", expected)?,
            first_moment: storage_buffer(ctx, "deform.first_moment", expected)?,
            second_moment: storage_buffer(ctx, "deform.second_moment", expected)?,
            workspace: None,
            max_chunk_rows: max_chunk_rows.clamp(1, binding_rows),
            resident_chunk: None,
            shape,
        };
        field.write_parameters(ctx, parameters)?;
        Ok(field)
    }

    /// The GEMM kernel this field's products run on.
    pub fn gemm_kernel(&self) -> GemmKernel {
        self.gemm
    }

    pub fn shape(&self) -> &FieldShape {
        &self.shape
    }

    pub fn parameter_count(&self) -> usize {
        self.shape.parameter_count()
    }

    pub fn write_parameters(&self, ctx: &GpuContext, values: &[f32]) -> Result<(), DeformError> {
        self.write(ctx, &self.parameters, values)
    }

    /// Restores the optimiser moments (checkpoint resume).
    pub fn write_moments(
        &self,
        ctx: &GpuContext,
        first: &[f32],
        second: &[f32],
    ) -> Result<(), DeformError> {
        self.write(ctx, &self.first_moment, first)?;
        self.write(ctx, &self.second_moment, second)
    }

    fn write(
        &self,
        ctx: &GpuContext,
        buffer: &wgpu::Buffer,
        values: &[f32],
    ) -> Result<(), DeformError> {
        if values.len() != self.parameter_count() {
            return Err(DeformError::ParameterCount {
                expected: self.parameter_count(),
                actual: values.len(),
            });
        }
        ctx.queue
            .write_buffer(buffer, 0, bytemuck::cast_slice(values));
        Ok(())
    }

    /// Reads a parameter-shaped buffer back (waits for submitted work).
    pub fn read(&self, ctx: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<f32>, DeformError> {
        let mut values: Vec<f32> = ctx.read_vec(buffer)?;
        values.truncate(self.parameter_count());
        Ok(values)
    }

    pub fn encode_zero_grads(&self, encoder: &mut segsplat_gpu::Encoder) {
        encoder.clear_buffer(&self.grads, 0, None);
    }

    /// Records one Adam step over every weight and bias.
    pub fn encode_adam(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        adam: &Adam,
        learning_rate: f32,
        step: u32,
    ) -> Result<(), DeformError> {
        let buffers = AdamBuffers {
            params: &self.parameters,
            grads: &self.grads,
            first_moment: &self.first_moment,
            second_moment: &self.second_moment,
        };
        adam.encode_step(
            ctx,
            encoder,
            &buffers,
            self.parameter_count() as u32,
            learning_rate,
            step,
        )?;
        Ok(())
    }

    fn chunks(&self, count: usize) -> Vec<(usize, usize)> {
        (0..count)
            .step_by(self.max_chunk_rows)
            .map(|first| (first, (count - first).min(self.max_chunk_rows)))
            .collect()
    }

    fn ensure_workspace(&mut self, ctx: &GpuContext, rows: usize) -> Result<(), DeformError> {
        if self.workspace.as_ref().is_some_and(|w| w.rows >= rows) {
            return Ok(());
        }
        self.resident_chunk = None;
        let shape = &self.shape;
        let width = shape.width as usize;
        let encoding = shape.encoding_width();
        let skip_width = encoding + if shape.skip_after > 0 { width } else { 0 };
        let heads = shape.head_outputs();
        let widest_layer = self
            .layers
            .iter()
            .map(|l| l.inputs * l.outputs)
            .max()
            .unwrap_or(1);
        // For the most splits any row count gets (`RowSplit::for_rows`): a product of fewer
        // rows than the workspace's can have more splits.
        let partial_words = widest_layer * MAX_SPLITS as usize;
        let hidden = (0..shape.depth as usize)
            .map(|l| storage_buffer(ctx, &format!("deform.hidden{l}"), rows * width))
            .collect::<Result<Vec<_>, _>>()?;
        self.workspace = Some(Workspace {
            rows,
            skip: storage_buffer(ctx, "deform.skip", rows * skip_width)?,
            hidden,
            head: storage_buffer(ctx, "deform.head", rows * heads)?,
            grad_ping: storage_buffer(ctx, "deform.grad_ping", rows * width)?,
            grad_pong: storage_buffer(ctx, "deform.grad_pong", rows * width)?,
            grad_head: storage_buffer(ctx, "deform.grad_head", rows * heads)?,
            partials: storage_buffer(ctx, "deform.partials", partial_words)?,
        });
        Ok(())
    }

    /// The chunk workspace ([`Self::ensure_workspace`] runs first in every pass).
    fn workspace(&self) -> Result<&Workspace, DeformError> {
        self.workspace.as_ref().ok_or_else(|| {
            DeformError::Gpu(GpuError::Device("deformation workspace missing".into()))
        })
    }

    fn skip_stride(&self) -> u32 {
        let skip = if self.shape.skip_after > 0 {
            self.shape.width
        } else {
            0
        };
        self.shape.encoding_width() as u32 + skip
    }

    /// Layer `index`'s output (0-based; the last layer is the head).
    fn output_slice(&self, index: usize) -> Slice {
        let depth = self.shape.depth as usize;
        if index == depth {
            return Slice {
                storage: Storage::Head,
                column: 0,
                row_stride: self.shape.head_outputs() as u32,
            };
        }
        if self.shape.skip_after as usize == index + 1 {
            return Slice {
                storage: Storage::Skip,
                column: self.shape.encoding_width() as u32,
                row_stride: self.skip_stride(),
            };
        }
        Slice {
            storage: Storage::Hidden(index),
            column: 0,
            row_stride: self.shape.width,
        }
    }

    /// Layer `index`'s input: the encoding, the skip concatenation, or the previous output.
    fn input_slice(&self, index: usize) -> Slice {
        if index == 0 || (self.shape.skip_after > 0 && index == self.shape.skip_after as usize) {
            return Slice {
                storage: Storage::Skip,
                column: 0,
                row_stride: self.skip_stride(),
            };
        }
        self.output_slice(index - 1)
    }

    fn buffer(workspace: &Workspace, storage: Storage) -> &wgpu::Buffer {
        match storage {
            Storage::Skip => &workspace.skip,
            Storage::Hidden(index) => &workspace.hidden[index],
            Storage::Head => &workspace.head,
        }
    }

    fn encode_chunk_forward(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        means: &wgpu::Buffer,
        first: usize,
        rows: usize,
        time: f32,
    ) -> Result<(), DeformError> {
        let workspace = self.workspace()?;
        self.kernels.encode(
            ctx,
            encoder,
            EncodeParams {
                count: rows as u32,
                first: first as u32,
                row_stride: self.skip_stride(),
                position_frequencies: self.shape.position_frequencies,
                time_frequencies: self.shape.time_frequencies,
                time,
                _pad: [0; 2],
            },
            means,
            &workspace.skip,
        );
        for (index, layer) in self.layers.iter().enumerate() {
            let input = self.input_slice(index);
            let output = self.output_slice(index);
            let params = GemmParams {
                rows: rows as u32,
                cols: layer.outputs as u32,
                depth: layer.inputs as u32,
                depth_per_split: layer.inputs as u32,
                a_offset: input.column,
                a_row_stride: input.row_stride,
                a_depth_stride: 1,
                b_offset: layer.weight_offset as u32,
                b_depth_stride: 1,
                b_col_stride: layer.inputs as u32,
                c_offset: output.column,
                c_row_stride: output.row_stride,
                bias_offset: layer.bias_offset as u32,
                flags: FLAG_BIAS | if layer.relu { FLAG_RELU } else { 0 },
                ..GemmParams::default()
            };
            self.kernels.gemm(
                ctx,
                encoder,
                GemmProduct::Forward,
                params,
                1,
                GemmBuffers {
                    a: Self::buffer(workspace, input.storage),
                    b: &self.parameters,
                    bias: &self.parameters,
                    mask: &self.parameters,
                    c: Self::buffer(workspace, output.storage),
                },
            );
        }
        Ok(())
    }

    fn apply_params(&self, first: usize, rows: usize) -> ApplyParams {
        ApplyParams {
            count: rows as u32,
            first: first as u32,
            head_stride: self.shape.head_outputs() as u32,
            screw: u32::from(self.shape.warp == WarpKind::Screw),
        }
    }

    /// Records the field at `time` over every Gaussian of `canonical` and writes the moved
    /// geometry into `deformed`.
    pub fn encode_forward(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        canonical: &GpuGaussians,
        deformed: &DeformedGeometry,
        time: f32,
    ) -> Result<(), DeformError> {
        let count = canonical.count();
        if deformed.capacity() < count {
            return Err(DeformError::GeometryTooSmall {
                count,
                capacity: deformed.capacity(),
            });
        }
        let chunks = self.chunks(count);
        let largest = chunks.iter().map(|c| c.1).max().unwrap_or(0);
        if largest == 0 {
            return Ok(());
        }
        self.ensure_workspace(ctx, largest)?;
        let p = &canonical.parameters;
        for &(first, rows) in &chunks {
            self.encode_chunk_forward(ctx, encoder, &p.means, first, rows, time)?;
            let workspace = self.workspace()?;
            self.kernels.apply_forward(
                ctx,
                encoder,
                self.apply_params(first, rows),
                &[
                    &workspace.head,
                    &p.means,
                    &p.rotations,
                    &p.log_scales,
                    &deformed.means,
                    &deformed.log_scales,
                    &deformed.rotations,
                ],
            );
            self.resident_chunk = Some(first);
        }
        Ok(())
    }

    /// Records the backward pass of the last [`Self::encode_forward`] (same `canonical` and
    /// `time`): `grads` holds d loss / d deformed geometry from the renders; afterwards its mean
    /// and rotation gradients are with respect to the canonical Gaussians, and the field's
    /// weight gradients are ADDED into [`Self::grads`].
    pub fn encode_backward(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        canonical: &GpuGaussians,
        grads: &GpuGaussianGrads,
        time: f32,
    ) -> Result<(), DeformError> {
        let count = canonical.count();
        let chunks = self.chunks(count);
        let largest = chunks.iter().map(|c| c.1).max().unwrap_or(0);
        if largest == 0 {
            return Ok(());
        }
        self.ensure_workspace(ctx, largest)?;
        let p = &canonical.parameters;
        let g = &grads.parameters;
        for &(first, rows) in chunks.iter().rev() {
            if self.resident_chunk != Some(first) {
                self.encode_chunk_forward(ctx, encoder, &p.means, first, rows, time)?;
                self.resident_chunk = Some(first);
            }
            let workspace = self.workspace()?;
            self.kernels.apply_backward(
                ctx,
                encoder,
                self.apply_params(first, rows),
                &[
                    &workspace.head,
                    &p.means,
                    &p.rotations,
                    &g.means,
                    &g.rotations,
                    &g.log_scales,
                    &workspace.grad_head,
                ],
            );
            self.encode_layers_backward(ctx, encoder, workspace, rows as u32);
        }
        Ok(())
    }

    /// Backpropagates `grad_head` through every layer of the resident chunk.
    fn encode_layers_backward(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        workspace: &Workspace,
        rows: u32,
    ) {
        let split = self.kernels.row_split(rows);
        let width = self.shape.width;
        // d loss / d pre-activation of the current layer, and its row stride.
        let mut grad = (&workspace.grad_head, self.shape.head_outputs() as u32);
        let mut spare = &workspace.grad_ping;
        let mut other = &workspace.grad_pong;
        for index in (0..self.layers.len()).rev() {
            let layer = self.layers[index];
            let input = self.input_slice(index);
            let input_buffer = Self::buffer(workspace, input.storage);
            let (outputs, inputs) = (layer.outputs as u32, layer.inputs as u32);
            // dW[o, i] = sum_n dZ[n, o] X[n, i], split over n.
            self.kernels.gemm(
                ctx,
                encoder,
                GemmProduct::WeightGradient,
                GemmParams {
                    rows: outputs,
                    cols: inputs,
                    depth: rows,
                    depth_per_split: split.rows_per_split,
                    a_offset: 0,
                    a_row_stride: 1,
                    a_depth_stride: grad.1,
                    b_offset: input.column,
                    b_depth_stride: input.row_stride,
                    b_col_stride: 1,
                    c_offset: 0,
                    c_row_stride: inputs,
                    c_split_stride: outputs * inputs,
                    ..GemmParams::default()
                },
                split.splits,
                GemmBuffers {
                    a: grad.0,
                    b: input_buffer,
                    bias: input_buffer,
                    mask: input_buffer,
                    c: &workspace.partials,
                },
            );
            self.kernels.split_reduce(
                ctx,
                encoder,
                &workspace.partials,
                outputs * inputs,
                split.splits,
                &self.grads,
                layer.weight_offset as u32,
            );
            self.kernels.column_sums(
                ctx,
                encoder,
                grad.0,
                0,
                grad.1,
                rows,
                outputs,
                split,
                &workspace.partials,
            );
            self.kernels.split_reduce(
                ctx,
                encoder,
                &workspace.partials,
                outputs,
                split.splits,
                &self.grads,
                layer.bias_offset as u32,
            );
            if index == 0 {
                break;
            }
            // dZ_prev[n, i] = (sum_o dZ[n, o] W[o, hidden_start + i]) * (H_prev[n, i] > 0):
            // only the previous layer's columns of the input carry a gradient back.
            let previous = self.output_slice(index - 1);
            let hidden_start = inputs - width;
            self.kernels.gemm(
                ctx,
                encoder,
                GemmProduct::InputGradient,
                GemmParams {
                    rows,
                    cols: width,
                    depth: outputs,
                    depth_per_split: outputs,
                    a_offset: 0,
                    a_row_stride: grad.1,
                    a_depth_stride: 1,
                    b_offset: layer.weight_offset as u32 + hidden_start,
                    b_depth_stride: inputs,
                    b_col_stride: 1,
                    c_offset: 0,
                    c_row_stride: width,
                    mask_offset: previous.column,
                    mask_row_stride: previous.row_stride,
                    flags: FLAG_MASK,
                    ..GemmParams::default()
                },
                1,
                GemmBuffers {
                    a: grad.0,
                    b: &self.parameters,
                    bias: &self.parameters,
                    mask: Self::buffer(workspace, previous.storage),
                    c: spare,
                },
            );
            grad = (spare, width);
            std::mem::swap(&mut spare, &mut other);
        }
    }
}
