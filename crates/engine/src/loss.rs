//! The render loss of 3DGS, `L = 0.8 * L1 + 0.2 * (1 - SSIM)`, forward and backward on the GPU.
//!
//! SSIM is computed as 3DGS computes it: an 11x11 Gaussian window (sigma 1.5), constants
//! C1 = 0.01^2 and C2 = 0.03^2, zero padding like its `conv2d`, the mean over pixels and RGB
//! channels. The window is separable, so four passes (filter moments horizontally; vertically,
//! then SSIM and its partials per pixel; filter the partials horizontally; vertically, then the
//! gradient) cost O(window) per pixel, not O(window^2).
//!
//! The same kernels give the Segment-then-Splat object loss: with an object mask the target is
//! `target * (object_ids[p] == object_id)`. A step's object losses run as one batch
//! ([`RenderLoss::encode_objects`]): one set of dispatches for all of them, each slot with its own
//! render, mask and scratch images.
//! An object's render and its mask usually cover a small part of the image, and where both are
//! zero over the SSIM window's reach the loss and its gradient are exactly zero: object losses first
//! mark each slot's 8x8 cells with content, then each cell's distance to it and two work lists
//! of the 16x16 tiles with a cell within reach (two small passes); the four passes run one
//! workgroup per listed (slot, tile), by indirect dispatch, and skip the cells beyond their reach
//! (`loss_skip.wgsl`: one cell for the first two passes, two for the last two). Their gradient
//! images are zeroed first, so what is skipped reads as zero.
//!
//! Outputs, for each loss: `weight * L` written to one slot of a small loss-values buffer (so a
//! training step records several losses without reading any back; the caller sums slots when it
//! reads them), and `weight * dL/d(rendered)` written over (not added to) a gradient image: every
//! render has its own gradient image, so the trainer sums losses by rendering separately.

use wgpu::util::DeviceExt;

mod checks;
mod passes;
mod scratch;

use checks::{check_content_hints, check_sizes, slot_table};
use passes::{LossDispatch, PassBindings};
use scratch::LossScratch;

use segsplat_gpu::kernel::wgsl_u32_constants;
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
/// Side of the squares object losses skip or compute (prepended as `SKIP_CELL`): a run's, and
/// the squares whose occupancy batched object renders mark.
const SKIP_CELL: u32 = LOSS_RUN;
const _: () = assert!(SKIP_CELL == crate::OCCUPANCY_CELL);
/// In a cell map ([`object_cell_map`]): the square's masked pixels belong to several objects.
pub const MIXED_CELL: u32 = u32::MAX;
/// Tiles one workgroup of `loss_content.wgsl` scans, side by side (prepended as
/// `CONTENT_TILES_PER_GROUP`): a CPU adapter pays per workgroup, and one tile's 16 rows are only
/// two of its 8-lane batches.
const CONTENT_TILES_PER_GROUP: u32 = 4;
/// Skip cells per loss tile, an upper bound per tile for the cells' buffers.
const CELLS_PER_TILE: u64 = (LOSS_TILE / SKIP_CELL) as u64 * (LOSS_TILE / SKIP_CELL) as u64;
/// Invocations of a per-pixel workgroup, each writing one loss partial sum.
const PER_PIXEL_INVOCATIONS: u32 = LOSS_TILE * LOSS_TILE / LOSS_RUN;
/// Bytes per pixel of the scratch images: four vec4 of filtered moments, three of partials.
const ROW_MOMENTS_BYTES_PER_PIXEL: u64 = 64;
const PARTIALS_BYTES_PER_PIXEL: u64 = 48;
/// Most object losses one set of dispatches computes (the kernels' per-slot table is this long,
/// prepended as `MAX_BATCH_SLOTS`); a larger batch runs in several.
pub const MAX_BATCH_SLOTS: u32 = 64;
/// Object-id maps one batch reads at most: one per level.
pub const MAX_ID_MAPS: usize = 3;
/// Scratch memory a batch of object losses may hold (each slot keeps its own intermediate
/// images); a batch needing more runs in several sets of dispatches.
const BATCH_SCRATCH_BUDGET_BYTES: u64 = 512 << 20;
/// The two work lists' indirect dispatch arguments before the list pass counts them.
const EMPTY_WORK_COUNTS: [u32; 6] = [0, 1, 1, 0, 1, 1];
/// Byte offsets of the near and far lists' dispatch arguments.
const NEAR_ARGUMENTS: u64 = 0;
const FAR_ARGUMENTS: u64 = 12;

const LOSS_COMMON: &str = include_str!("loss/loss_common.wgsl");
const LOSS_ID_MAPS: &str = include_str!("loss/loss_id_maps.wgsl");
const LOSS_INPUTS: &str = include_str!("loss/loss_inputs.wgsl");
const LOSS_MOMENTS_HORIZONTAL: &str = include_str!("loss/loss_moments_horizontal.wgsl");
const LOSS_PER_PIXEL: &str = include_str!("loss/loss_per_pixel.wgsl");
const LOSS_PARTIALS_RUN: &str = include_str!("loss/loss_partials_run.wgsl");
const LOSS_PARTIALS_HORIZONTAL: &str = include_str!("loss/loss_partials_horizontal.wgsl");
const LOSS_GRADIENT: &str = include_str!("loss/loss_gradient.wgsl");
const LOSS_REDUCE: &str = include_str!("loss/loss_reduce.wgsl");
const LOSS_SKIP: &str = include_str!("loss/loss_skip.wgsl");
const LOSS_CONTENT: &str = include_str!("loss/loss_content.wgsl");
const LOSS_CELL_CONTENT: &str = include_str!("loss/loss_cell_content.wgsl");
const LOSS_WORK: &str = include_str!("loss/loss_work.wgsl");
const LOSS_WORK_LISTS: &str = include_str!("loss/loss_work_lists.wgsl");

#[derive(Debug, thiserror::Error)]
pub enum LossError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("render loss needs a non-empty image, got {width}x{height}")]
    EmptyImage { width: u32, height: u32 },
    #[error("a batch of object losses reads at most {MAX_ID_MAPS} id maps, got {0}")]
    TooManyIdMaps(usize),
    #[error("object loss slot {slot} reads id map {id_map}, but the batch has {maps}")]
    UnknownIdMap {
        slot: usize,
        id_map: u32,
        maps: usize,
    },
    #[error("a batch of object losses has {cell_maps} cell maps for {id_maps} id maps")]
    CellMapCount { cell_maps: usize, id_maps: usize },
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
            ("MAX_BATCH_SLOTS", MAX_BATCH_SLOTS),
            ("CONTENT_TILES_PER_GROUP", CONTENT_TILES_PER_GROUP),
            ("MIXED_CELL", MIXED_CELL),
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

/// One object loss of a batch: the target masked to the pixels of `id_maps[id_map]` equal to
/// `object_id`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectLossSlot {
    pub id_map: u32,
    pub object_id: u32,
}

/// A batch of object losses over one target image: slot `s` compares rendered image
/// `rendered_index + s` with the target masked to its object.
#[derive(Debug, Clone, Copy)]
pub struct ObjectLossImages<'a> {
    pub rendered: &'a wgpu::Buffer,
    pub rendered_index: u32,
    pub target: &'a wgpu::Buffer,
    /// One u32 object id per pixel each, row-major; at most [`MAX_ID_MAPS`].
    pub id_maps: &'a [&'a wgpu::Buffer],
    pub slots: &'a [ObjectLossSlot],
    pub width: u32,
    pub height: u32,
    /// Where the renders and masks hold content, when known: then a small pass over squares
    /// replaces one that reads every pixel of every slot. The losses are the same either way.
    pub content: Option<ObjectContentHints<'a>>,
}

/// What a batch of object losses knows of its inputs' content, per [`crate::OCCUPANCY_CELL`]
/// square (`ceil(width / OCCUPANCY_CELL)` across, `ceil(height / OCCUPANCY_CELL)` down,
/// row-major).
#[derive(Debug, Clone, Copy)]
pub struct ObjectContentHints<'a> {
    /// Per rendered image, indexed as the rendered buffer's images are: a u32 per square, non-zero
    /// where some pixel's colour is (`ObjectBatchOutput::occupancy`).
    pub occupancy: &'a wgpu::Buffer,
    /// Each id map's [`object_cell_map`], in the order of `id_maps`.
    pub cell_maps: &'a [&'a wgpu::Buffer],
}

/// The cell map of an id map `width` pixels wide: per [`crate::OCCUPANCY_CELL`] square,
/// row-major, 0 where no pixel has an object, the id where every pixel with one has the same,
/// and [`MIXED_CELL`] where they differ (the loss then reads the square's ids).
pub fn object_cell_map(ids: &[u32], width: u32) -> Vec<u32> {
    let width = width.max(1) as usize;
    let height = ids.len().div_ceil(width);
    let cell = SKIP_CELL as usize;
    let cells_x = width.div_ceil(cell);
    let mut map = vec![0u32; cells_x * height.div_ceil(cell)];
    for (row, row_ids) in ids.chunks(width).enumerate() {
        for (x, &id) in row_ids.iter().enumerate() {
            let square = &mut map[row / cell * cells_x + x / cell];
            *square = match *square {
                _ if id == 0 => *square,
                0 => id,
                current if current == id => current,
                _ => MIXED_CELL,
            };
        }
    }
    map
}

/// Where one loss writes; for a batch, where its first slot writes (slot `s` writes gradient
/// image `grad_index + s` and loss value `loss_slot + s`).
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

/// Fused L1 + D-SSIM loss, forward and backward (see the module doc).
#[derive(Debug)]
pub struct RenderLoss {
    moments_horizontal: Kernel,
    per_pixel: Kernel,
    partials_horizontal: Kernel,
    gradient: Kernel,
    reduce: Kernel,
    /// Object losses: which cells hold content, how far each cell is from it and which tiles
    /// the passes must compute, so they skip what is exactly zero.
    tile_content: Kernel,
    /// The same from the renders' occupancy and the masks' cell maps, where the caller has them.
    cell_content: Kernel,
    work_lists: Kernel,
    /// Bound as the object ids and the work lists of a loss without a mask.
    no_mask: wgpu::Buffer,
    /// [`EMPTY_WORK_COUNTS`], copied over the dispatch arguments before each batch.
    empty_work_counts: wgpu::Buffer,
    scratch: Option<LossScratch>,
}

impl RenderLoss {
    pub fn new(ctx: &GpuContext) -> Result<Self, LossError> {
        let constants = loss_constants_wgsl();
        let kernel = |label, sources: &[&str], entry| Kernel::new(ctx, label, sources, entry, &[]);
        let pass = |source| {
            [
                constants.as_str(),
                LOSS_COMMON,
                LOSS_SKIP,
                LOSS_WORK,
                LOSS_ID_MAPS,
                LOSS_INPUTS,
                source,
            ]
        };
        let partials_pass = |source| {
            [
                constants.as_str(),
                LOSS_COMMON,
                LOSS_SKIP,
                LOSS_WORK,
                LOSS_PARTIALS_RUN,
                source,
            ]
        };
        let plain = |source| [constants.as_str(), LOSS_COMMON, source];
        Ok(Self {
            moments_horizontal: kernel(
                "loss_moments_horizontal",
                &pass(LOSS_MOMENTS_HORIZONTAL),
                "filter_moments_horizontal",
            )?,
            per_pixel: kernel("loss_per_pixel", &pass(LOSS_PER_PIXEL), "ssim_per_pixel")?,
            partials_horizontal: kernel(
                "loss_partials_horizontal",
                &partials_pass(LOSS_PARTIALS_HORIZONTAL),
                "filter_partials_horizontal",
            )?,
            gradient: kernel(
                "loss_gradient",
                &[
                    constants.as_str(),
                    LOSS_COMMON,
                    LOSS_SKIP,
                    LOSS_WORK,
                    LOSS_ID_MAPS,
                    LOSS_INPUTS,
                    LOSS_PARTIALS_RUN,
                    LOSS_GRADIENT,
                ],
                "loss_gradient",
            )?,
            reduce: kernel("loss_reduce", &plain(LOSS_REDUCE), "reduce_loss")?,
            tile_content: kernel(
                "loss_tile_content",
                &[
                    constants.as_str(),
                    LOSS_COMMON,
                    LOSS_ID_MAPS,
                    LOSS_INPUTS,
                    LOSS_CONTENT,
                ],
                "loss_tile_content",
            )?,
            cell_content: kernel(
                "loss_cell_content",
                &[
                    constants.as_str(),
                    LOSS_COMMON,
                    LOSS_ID_MAPS,
                    LOSS_CELL_CONTENT,
                ],
                "loss_cell_content",
            )?,
            work_lists: kernel(
                "loss_work_lists",
                &[constants.as_str(), LOSS_COMMON, LOSS_SKIP, LOSS_WORK_LISTS],
                "loss_work_lists",
            )?,
            no_mask: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("loss no mask"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
            empty_work_counts: ctx
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("loss empty work counts"),
                    contents: bytemuck::cast_slice(&EMPTY_WORK_COUNTS),
                    usage: wgpu::BufferUsages::COPY_SRC,
                }),
            scratch: None,
        })
    }

    /// Records the loss of `images` scaled by `weight`: `weight * L` to
    /// `outputs.loss_values[outputs.loss_slot]`, `weight * dL/d(rendered)` over
    /// `outputs.rendered_grad`.
    pub fn encode(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        images: &LossImages<'_>,
        weight: f32,
        outputs: &LossOutputs<'_>,
    ) -> Result<(), LossError> {
        if let Some(mask) = images.target_mask {
            let id_maps = [mask.object_ids];
            let slots = [ObjectLossSlot {
                id_map: 0,
                object_id: mask.object_id,
            }];
            let batch = ObjectLossImages {
                rendered: images.rendered,
                rendered_index: images.rendered_index,
                target: images.target,
                id_maps: &id_maps,
                slots: &slots,
                width: images.width,
                height: images.height,
                content: None,
            };
            return self.encode_objects(ctx, encoder, &batch, weight, outputs);
        }
        check_sizes(images, &[], 1, outputs)?;
        let (width, height) = (images.width, images.height);
        self.reserve(ctx, width, height)?;
        let Some(scratch) = self.scratch.as_ref() else {
            return Err(LossError::EmptyImage { width, height });
        };
        let params = LossDispatch {
            width,
            height,
            use_mask: false,
            weight,
            first_rendered: images.rendered_index,
            first_grad: outputs.grad_index,
            first_loss_slot: outputs.loss_slot,
            slots: &[],
        }
        .uniform_params(ctx);
        let maps = [&self.no_mask; MAX_ID_MAPS];
        let bindings = PassBindings {
            params: &params,
            rendered: images.rendered,
            target: images.target,
            id_maps: maps,
            near_items: &self.no_mask,
            far_items: &self.no_mask,
            rendered_grad: outputs.rendered_grad,
            loss_values: outputs.loss_values,
        };
        let tiles = [width.div_ceil(LOSS_TILE), height.div_ceil(LOSS_TILE), 1];
        self.encode_passes(
            ctx,
            encoder,
            scratch,
            &bindings,
            1,
            &|kernel, encoder, bind, _| kernel.dispatch(encoder, bind, tiles),
        );
        Ok(())
    }

    /// Records a batch of object losses scaled by `weight` (see [`ObjectLossImages`] and
    /// [`LossOutputs`]): one set of dispatches for as many slots as fit at once.
    pub fn encode_objects(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        images: &ObjectLossImages<'_>,
        weight: f32,
        outputs: &LossOutputs<'_>,
    ) -> Result<(), LossError> {
        let (width, height) = (images.width, images.height);
        let single = LossImages {
            rendered: images.rendered,
            rendered_index: images.rendered_index,
            target: images.target,
            target_mask: None,
            width,
            height,
        };
        check_sizes(&single, images.id_maps, images.slots.len() as u32, outputs)?;
        if let Some(content) = &images.content {
            check_content_hints(images, content)?;
        }
        let table = slot_table(images)?;
        if table.is_empty() {
            return Ok(());
        }
        let pixels = u64::from(width) * u64::from(height);
        let tiles = u64::from(width.div_ceil(LOSS_TILE)) * u64::from(height.div_ceil(LOSS_TILE));
        let per_dispatch = Self::slots_per_dispatch(ctx, pixels, tiles) as usize;
        self.reserve_slots(ctx, width, height, table.len().min(per_dispatch) as u32)?;
        let Some(scratch) = self.scratch.as_ref() else {
            return Err(LossError::EmptyImage { width, height });
        };
        let first_map = images.id_maps[0];
        let maps: [&wgpu::Buffer; MAX_ID_MAPS] =
            std::array::from_fn(|index| images.id_maps.get(index).copied().unwrap_or(first_map));
        for (chunk_index, chunk) in table.chunks(per_dispatch).enumerate() {
            let first = (chunk_index * per_dispatch) as u32;
            let count = chunk.len() as u32;
            let params = LossDispatch {
                width,
                height,
                use_mask: true,
                weight,
                first_rendered: images.rendered_index + first,
                first_grad: outputs.grad_index + first,
                first_loss_slot: outputs.loss_slot + first,
                slots: chunk,
            }
            .uniform_params(ctx);
            let bindings = PassBindings {
                params: &params,
                rendered: images.rendered,
                target: images.target,
                id_maps: maps,
                near_items: &scratch.near_items,
                far_items: &scratch.far_items,
                rendered_grad: outputs.rendered_grad,
                loss_values: outputs.loss_values,
            };
            self.encode_work_lists(
                ctx,
                encoder,
                scratch,
                &bindings,
                images.content.as_ref(),
                [width, height],
                count,
            );
            encoder.clear_buffer(
                &scratch.loss_partials,
                0,
                Some(tiles * u64::from(count) * u64::from(PER_PIXEL_INVOCATIONS) * 4),
            );
            encoder.clear_buffer(
                outputs.rendered_grad,
                u64::from(outputs.grad_index + first) * pixels * 16,
                Some(u64::from(count) * pixels * 16),
            );
            self.encode_passes(
                ctx,
                encoder,
                scratch,
                &bindings,
                count,
                &|kernel, encoder, bind, far| {
                    let offset = if far { FAR_ARGUMENTS } else { NEAR_ARGUMENTS };
                    kernel.dispatch_indirect(encoder, bind, &scratch.work_counts, offset)
                },
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_map_names_the_one_object_of_a_square_or_marks_it_mixed() {
        // 10 x 9 pixels: squares of 8, so 2 x 2 of them, the last column and row partial.
        let (width, height) = (10usize, 9usize);
        let mut ids = vec![0u32; width * height];
        let mut set = |x: usize, y: usize, id: u32| ids[y * width + x] = id;
        set(1, 1, 5);
        set(7, 7, 5);
        set(9, 0, 3);
        set(8, 8, 3);
        set(9, 8, 4);
        assert_eq!(
            object_cell_map(&ids, width as u32),
            vec![5, 3, 0, MIXED_CELL],
            "top left one object, top right another, bottom left empty, bottom right two"
        );
    }
}
