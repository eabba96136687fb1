//! The render loss of 3DGS, `L = 0.8 * L1 + 0.2 * (1 - SSIM)`, forward and backward on the GPU.
//!
//! SSIM is computed as 3DGS computes it: an 11x11 Gaussian window (sigma 1.5), constants
//! C1 = 0.01^2 and C2 = 0.03^2, zero padding like its `conv2d`, the mean over pixels and RGB
//! channels. The window is separable, so four passes (filter moments horizontally; vertically,
//! then SSIM and its partials per pixel; filter the partials horizontally; vertically, then the
//! gradient) cost O(window) per pixel, not O(window^2).
//!
//! The same kernels give the Segment-then-Splat object loss: with an [`ObjectMask`] the target is
//! `target * (object_ids[p] == object_id)`.
//! An object's render and its mask usually cover a small part of the image, and where both are
//! zero over the SSIM window's reach the loss and its gradient are exactly zero: object losses first
//! mark the 8x8 cells with content and each cell's distance to it (two small passes), and the
//! four passes skip the cells beyond their reach (`loss_skip.wgsl`: one cell for the first two
//! passes, two for the last two), writing zero gradients there.
//!
//! Outputs, for one call: `weight * L` written to one slot of a small loss-values buffer (so a
//! training step records several losses without reading any back; the caller sums slots when it
//! reads them), and `weight * dL/d(rendered)` written over (not added to) a gradient image: every
//! render has its own gradient image, so the trainer sums losses by rendering separately.

use wgpu::util::DeviceExt;

use segsplat_gpu::kernel::wgsl_u32_constants;
use segsplat_gpu::validation::validated;
use segsplat_gpu::{GpuContext, GpuError, Kernel};

/// Weight of the L1 term.
pub const L1_WEIGHT: f32 = 0.8;
/// Weight of the D-SSIM term, `1 - SSIM` (3DGS's `lambda_dssim`).
pub const DSSIM_WEIGHT: f32 = 0.2;
/// SSIM stabilisers for intensities in [0, 1].
pub const SSIM_C1: f32 = 0.01 * 0.01;
pub const SSIM_C2: f32 = 0.03 * 0.03;
/// Side of the SSIM window and the standard deviation of its Gaussian, in pixels.
pub const SSIM_WINDOW_SIZE: usize = 11;
pub const SSIM_WINDOW_SIGMA: f64 = 1.5;

/// Pixels per side of the per-pixel kernels' workgroups (prepended as `LOSS_TILE`).
const LOSS_TILE: u32 = 16;
/// Pixels each per-pixel invocation filters (prepended as `LOSS_RUN`).
const LOSS_RUN: u32 = 8;
/// Side of the squares object losses skip or compute (prepended as `SKIP_CELL`): a run's.
const SKIP_CELL: u32 = LOSS_RUN;
/// Skip cells per loss tile, an upper bound per tile for the cells' buffers.
const CELLS_PER_TILE: u64 = (LOSS_TILE / SKIP_CELL) as u64 * (LOSS_TILE / SKIP_CELL) as u64;
/// Invocations of a per-pixel workgroup, each writing one loss partial sum.
const PER_PIXEL_INVOCATIONS: u32 = LOSS_TILE * LOSS_TILE / LOSS_RUN;
/// Bytes per pixel of the scratch images: four vec4 of filtered moments, three of partials.
const ROW_MOMENTS_BYTES_PER_PIXEL: u64 = 64;
const PARTIALS_BYTES_PER_PIXEL: u64 = 48;

const LOSS_COMMON: &str = include_str!("loss/loss_common.wgsl");
const LOSS_INPUTS: &str = include_str!("loss/loss_inputs.wgsl");
const LOSS_MOMENTS_HORIZONTAL: &str = include_str!("loss/loss_moments_horizontal.wgsl");
const LOSS_PER_PIXEL: &str = include_str!("loss/loss_per_pixel.wgsl");
const LOSS_PARTIALS_RUN: &str = include_str!("loss/loss_partials_run.wgsl");
const LOSS_PARTIALS_HORIZONTAL: &str = include_str!("loss/loss_partials_horizontal.wgsl");
const LOSS_GRADIENT: &str = include_str!("loss/loss_gradient.wgsl");
const LOSS_REDUCE: &str = include_str!("loss/loss_reduce.wgsl");
const LOSS_SKIP: &str = include_str!("loss/loss_skip.wgsl");
const LOSS_CONTENT: &str = include_str!("loss/loss_content.wgsl");
const LOSS_DISTANCE: &str = include_str!("loss/loss_distance.wgsl");

#[derive(Debug, thiserror::Error)]
pub enum LossError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("render loss needs a non-empty image, got {width}x{height}")]
    EmptyImage { width: u32, height: u32 },
    #[error(
        "render loss: {what} holds {actual_bytes} bytes but a {width}x{height} image needs {needed_bytes}"
    )]
    BufferTooSmall {
        what: &'static str,
        actual_bytes: u64,
        needed_bytes: u64,
        width: u32,
        height: u32,
    },
}

/// The normalised 1D Gaussian of the SSIM window (its outer product is 3DGS's 2D window).
pub fn ssim_window() -> [f64; SSIM_WINDOW_SIZE] {
    let radius = (SSIM_WINDOW_SIZE / 2) as f64;
    let mut taps = [0.0; SSIM_WINDOW_SIZE];
    for (index, tap) in taps.iter_mut().enumerate() {
        let offset = index as f64 - radius;
        *tap = (-offset * offset / (2.0 * SSIM_WINDOW_SIGMA * SSIM_WINDOW_SIGMA)).exp();
    }
    let sum: f64 = taps.iter().sum();
    taps.map(|tap| tap / sum)
}

/// The constants the loss kernels expect ahead of `loss_common.wgsl`.
fn loss_constants_wgsl() -> String {
    let taps: Vec<String> = ssim_window()
        .iter()
        .map(|&tap| format!("{:?}", tap as f32))
        .collect();
    format!(
        "const SSIM_WINDOW = array<f32, {size}>({taps});\n\
         const SSIM_C1: f32 = {c1:?};\nconst SSIM_C2: f32 = {c2:?};\n\
         const L1_WEIGHT: f32 = {l1:?};\nconst DSSIM_WEIGHT: f32 = {dssim:?};\n{tiles}",
        size = SSIM_WINDOW_SIZE,
        taps = taps.join(", "),
        c1 = SSIM_C1,
        c2 = SSIM_C2,
        tiles = wgsl_u32_constants(&[
            ("LOSS_TILE", LOSS_TILE),
            ("LOSS_RUN", LOSS_RUN),
            ("SKIP_CELL", SKIP_CELL),
        ]),
        l1 = L1_WEIGHT,
        dssim = DSSIM_WEIGHT,
    )
}

/// Restricts the target to one object: `target * (object_ids[p] == object_id)`.
#[derive(Debug, Clone, Copy)]
pub struct ObjectMask<'a> {
    /// One u32 object id per pixel, row-major.
    pub object_ids: &'a wgpu::Buffer,
    pub object_id: u32,
}

/// The images one loss compares, each `array<vec4<f32>>` of `width * height` pixels, row-major,
/// RGB in xyz (w, the alpha, is ignored).
#[derive(Debug, Clone, Copy)]
pub struct LossImages<'a> {
    /// Holds the rendered image as its `rendered_index`-th image of `width * height` pixels
    /// (a batch of object renders is one buffer of images back to back).
    pub rendered: &'a wgpu::Buffer,
    pub rendered_index: u32,
    pub target: &'a wgpu::Buffer,
    pub target_mask: Option<ObjectMask<'a>>,
    pub width: u32,
    pub height: u32,
}

/// Where one loss writes.
#[derive(Debug, Clone, Copy)]
pub struct LossOutputs<'a> {
    /// Its `grad_index`-th image of `width * height` pixels is overwritten with
    /// `weight * dL/d(rendered)`, same layout as the rendered image (w = 0).
    pub rendered_grad: &'a wgpu::Buffer,
    pub grad_index: u32,
    /// f32 slots; `loss_values[loss_slot]` is overwritten with `weight * L`.
    pub loss_values: &'a wgpu::Buffer,
    pub loss_slot: u32,
}

/// Uniform block of `loss_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LossParams {
    width: u32,
    height: u32,
    use_mask: u32,
    object_id: u32,
    weight: f32,
    inv_value_count: f32,
    loss_slot: u32,
    partial_count: u32,
    rendered_base: u32,
    grad_base: u32,
    padding: [u32; 2],
}

/// Intermediate images for one image size; grown, never shrunk.
#[derive(Debug)]
struct LossScratch {
    pixel_capacity: u64,
    /// Workgroups of the per-pixel kernel, one loss partial sum each.
    tile_capacity: u64,
    row_moments: wgpu::Buffer,
    ssim_partials: wgpu::Buffer,
    row_partials: wgpu::Buffer,
    loss_partials: wgpu::Buffer,
    /// Per skip cell: content flag, then distance in cells to content (object losses).
    tile_content: wgpu::Buffer,
    tile_distance: wgpu::Buffer,
}

/// Fused L1 + D-SSIM loss, forward and backward (see the module doc).
#[derive(Debug)]
pub struct RenderLoss {
    moments_horizontal: Kernel,
    per_pixel: Kernel,
    partials_horizontal: Kernel,
    gradient: Kernel,
    reduce: Kernel,
    /// Object losses: which cells hold content and how far each cell is from it, so the passes
    /// skip cells whose loss and gradient are exactly zero.
    tile_content: Kernel,
    tile_distance: Kernel,
    /// Bound as the object ids when no mask is given.
    no_mask: wgpu::Buffer,
    scratch: Option<LossScratch>,
}

impl RenderLoss {
    pub fn new(ctx: &GpuContext) -> Result<Self, LossError> {
        let constants = loss_constants_wgsl();
        let kernel = |label, sources: &[&str], entry| {
            validated(ctx, label, || Kernel::new(ctx, label, sources, entry, &[]))
        };
        let with_inputs = |source| {
            [
                constants.as_str(),
                LOSS_COMMON,
                LOSS_SKIP,
                LOSS_INPUTS,
                source,
            ]
        };
        let plain = |source| [constants.as_str(), LOSS_COMMON, source];
        Ok(Self {
            moments_horizontal: kernel(
                "loss_moments_horizontal",
                &with_inputs(LOSS_MOMENTS_HORIZONTAL),
                "filter_moments_horizontal",
            )?,
            per_pixel: kernel(
                "loss_per_pixel",
                &with_inputs(LOSS_PER_PIXEL),
                "ssim_per_pixel",
            )?,
            partials_horizontal: kernel(
                "loss_partials_horizontal",
                &[
                    constants.as_str(),
                    LOSS_COMMON,
                    LOSS_SKIP,
                    LOSS_PARTIALS_RUN,
                    LOSS_PARTIALS_HORIZONTAL,
                ],
                "filter_partials_horizontal",
            )?,
            gradient: kernel(
                "loss_gradient",
                &[
                    constants.as_str(),
                    LOSS_COMMON,
                    LOSS_SKIP,
                    LOSS_INPUTS,
                    LOSS_PARTIALS_RUN,
                    LOSS_GRADIENT,
                ],
                "loss_gradient",
            )?,
            reduce: kernel("loss_reduce", &plain(LOSS_REDUCE), "reduce_loss")?,
            tile_content: kernel(
                "loss_tile_content",
                &[constants.as_str(), LOSS_COMMON, LOSS_INPUTS, LOSS_CONTENT],
                "loss_tile_content",
            )?,
            tile_distance: kernel(
                "loss_tile_distance",
                &[constants.as_str(), LOSS_COMMON, LOSS_SKIP, LOSS_DISTANCE],
                "loss_tile_distance",
            )?,
            no_mask: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("loss no mask"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
            scratch: None,
        })
    }

    /// Allocates intermediates for a `width x height` image (kept for smaller ones), failing when
    /// they would exceed the adapter's storage binding limit.
    pub fn reserve(&mut self, ctx: &GpuContext, width: u32, height: u32) -> Result<(), LossError> {
        let pixels = u64::from(width) * u64::from(height);
        if pixels == 0 {
            return Err(LossError::EmptyImage { width, height });
        }
        let tiles = u64::from(width.div_ceil(LOSS_TILE)) * u64::from(height.div_ceil(LOSS_TILE));
        if self.scratch.as_ref().is_some_and(|scratch| {
            scratch.pixel_capacity >= pixels && scratch.tile_capacity >= tiles
        }) {
            return Ok(());
        }
        let (pixels, tiles) = match &self.scratch {
            Some(scratch) => (
                pixels.max(scratch.pixel_capacity),
                tiles.max(scratch.tile_capacity),
            ),
            None => (pixels, tiles),
        };
        let storage = |label, size| ctx.storage_buffer(label, size);
        self.scratch = Some(LossScratch {
            pixel_capacity: pixels,
            tile_capacity: tiles,
            row_moments: storage("loss row moments", pixels * ROW_MOMENTS_BYTES_PER_PIXEL)?,
            ssim_partials: storage("loss ssim partials", pixels * PARTIALS_BYTES_PER_PIXEL)?,
            row_partials: storage("loss row partials", pixels * PARTIALS_BYTES_PER_PIXEL)?,
            loss_partials: storage(
                "loss partial sums",
                tiles * u64::from(PER_PIXEL_INVOCATIONS) * 4,
            )?,
            tile_content: storage("loss cell content", tiles * CELLS_PER_TILE * 4)?,
            tile_distance: storage("loss cell distance", tiles * CELLS_PER_TILE * 4)?,
        });
        Ok(())
    }

    /// Records the loss of `images` scaled by `weight`: `weight * L` to
    /// `outputs.loss_values[outputs.loss_slot]`, `weight * dL/d(rendered)` over
    /// `outputs.rendered_grad`.
    pub fn encode(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        images: &LossImages<'_>,
        weight: f32,
        outputs: &LossOutputs<'_>,
    ) -> Result<(), LossError> {
        let LossImages {
            rendered,
            target,
            target_mask,
            width,
            height,
            ..
        } = *images;
        check_sizes(images, outputs)?;
        self.reserve(ctx, width, height)?;
        let Some(scratch) = self.scratch.as_ref() else {
            return Err(LossError::EmptyImage { width, height });
        };
        let groups = [width.div_ceil(LOSS_TILE), height.div_ceil(LOSS_TILE), 1];
        let params = LossParams {
            width,
            height,
            use_mask: u32::from(target_mask.is_some()),
            object_id: target_mask.map_or(0, |mask| mask.object_id),
            weight,
            inv_value_count: (1.0 / (f64::from(width) * f64::from(height) * 3.0)) as f32,
            loss_slot: outputs.loss_slot,
            partial_count: groups[0] * groups[1] * PER_PIXEL_INVOCATIONS,
            rendered_base: images.rendered_index * width * height,
            grad_base: outputs.grad_index * width * height,
            padding: [0; 2],
        };
        // A buffer per call (not queue.write_buffer on a shared one) so several losses recorded
        // before one submit each keep their own parameters.
        let params = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("loss params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let object_ids = target_mask.map_or(&self.no_mask, |mask| mask.object_ids);
        let inputs = [&params, rendered, target, object_ids];
        if target_mask.is_some() {
            encoder.clear_buffer(&scratch.tile_content, 0, None);
            let bind = self.tile_content.bind(
                ctx,
                &[
                    inputs[0],
                    inputs[1],
                    inputs[2],
                    inputs[3],
                    &scratch.tile_content,
                ],
            );
            self.tile_content.dispatch(encoder, &bind, groups);
            let bind = self.tile_distance.bind(
                ctx,
                &[&params, &scratch.tile_content, &scratch.tile_distance],
            );
            let cells = width.div_ceil(SKIP_CELL) * height.div_ceil(SKIP_CELL);
            self.tile_distance
                .dispatch(encoder, &bind, [cells.div_ceil(64), 1, 1]);
        }

        let bind = self.moments_horizontal.bind(
            ctx,
            &[
                inputs[0],
                inputs[1],
                inputs[2],
                inputs[3],
                &scratch.row_moments,
                &scratch.tile_distance,
            ],
        );
        self.moments_horizontal.dispatch(encoder, &bind, groups);
        let bind = self.per_pixel.bind(
            ctx,
            &[
                inputs[0],
                inputs[1],
                inputs[2],
                inputs[3],
                &scratch.row_moments,
                &scratch.ssim_partials,
                &scratch.loss_partials,
                &scratch.tile_distance,
            ],
        );
        self.per_pixel.dispatch(encoder, &bind, groups);
        let bind = self.partials_horizontal.bind(
            ctx,
            &[
                &params,
                &scratch.ssim_partials,
                &scratch.row_partials,
                &scratch.tile_distance,
            ],
        );
        self.partials_horizontal.dispatch(encoder, &bind, groups);
        let bind = self.gradient.bind(
            ctx,
            &[
                inputs[0],
                inputs[1],
                inputs[2],
                inputs[3],
                &scratch.row_partials,
                outputs.rendered_grad,
                &scratch.tile_distance,
            ],
        );
        self.gradient.dispatch(encoder, &bind, groups);
        let bind = self
            .reduce
            .bind(ctx, &[&params, &scratch.loss_partials, outputs.loss_values]);
        self.reduce.dispatch(encoder, &bind, [1, 1, 1]);
        Ok(())
    }
}

/// Rejects buffers too small for the image, which the kernels would otherwise read as zeros.
fn check_sizes(images: &LossImages<'_>, outputs: &LossOutputs<'_>) -> Result<(), LossError> {
    let (width, height) = (images.width, images.height);
    let pixels = u64::from(width) * u64::from(height);
    if pixels == 0 {
        return Err(LossError::EmptyImage { width, height });
    }
    let mut required = vec![
        (
            "rendered image",
            images.rendered,
            (u64::from(images.rendered_index) + 1) * pixels * 16,
        ),
        ("target image", images.target, pixels * 16),
        (
            "rendered gradient",
            outputs.rendered_grad,
            (u64::from(outputs.grad_index) + 1) * pixels * 16,
        ),
        (
            "loss values",
            outputs.loss_values,
            (u64::from(outputs.loss_slot) + 1) * 4,
        ),
    ];
    if let Some(mask) = images.target_mask {
        required.push(("target object ids", mask.object_ids, pixels * 4));
    }
    for (what, buffer, needed_bytes) in required {
        if buffer.size() < needed_bytes {
            return Err(LossError::BufferTooSmall {
                what,
                actual_bytes: buffer.size(),
                needed_bytes,
                width,
                height,
            });
        }
    }
    Ok(())
}
