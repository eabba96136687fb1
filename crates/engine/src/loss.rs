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

use segsplat_gpu::kernel::wgsl_u32_constants;
use segsplat_gpu::{GpuContext, GpuError, Kernel, UniformParams};

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

/// Uniform block of `loss_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LossParams {
    width: u32,
    height: u32,
    use_mask: u32,
    slot_count: u32,
    weight: f32,
    inv_value_count: f32,
    first_loss_slot: u32,
    first_rendered: u32,
    first_grad: u32,
    partial_count: u32,
    tiles_x: u32,
    padding: u32,
    /// Per slot: (id map, object id, 0, 0).
    slots: [[u32; 4]; MAX_BATCH_SLOTS as usize],
}

/// Intermediate images for up to `slot_capacity` losses of one image size; grown, never shrunk.
#[derive(Debug)]
struct LossScratch {
    /// Per slot.
    pixel_capacity: u64,
    /// Per slot: workgroups of the per-pixel kernel, one loss partial sum per invocation each.
    tile_capacity: u64,
    slot_capacity: u64,
    row_moments: wgpu::Buffer,
    ssim_partials: wgpu::Buffer,
    row_partials: wgpu::Buffer,
    loss_partials: wgpu::Buffer,
    /// Per slot and skip cell: content flag, then distance in cells to content (object losses).
    tile_content: wgpu::Buffer,
    tile_distance: wgpu::Buffer,
    /// (slot, tile) pairs within reach 1 and 2 of content, and their dispatch arguments.
    near_items: wgpu::Buffer,
    far_items: wgpu::Buffer,
    work_counts: wgpu::Buffer,
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

/// A batch's slots, checked, in the kernels' table layout.
fn slot_table(images: &ObjectLossImages<'_>) -> Result<Vec<[u32; 4]>, LossError> {
    if images.id_maps.len() > MAX_ID_MAPS {
        return Err(LossError::TooManyIdMaps(images.id_maps.len()));
    }
    images
        .slots
        .iter()
        .enumerate()
        .map(|(slot, object)| {
            if object.id_map as usize >= images.id_maps.len() {
                return Err(LossError::UnknownIdMap {
                    slot,
                    id_map: object.id_map,
                    maps: images.id_maps.len(),
                });
            }
            Ok([object.id_map, object.object_id, 0, 0])
        })
        .collect()
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

    /// Allocates intermediates for one `width x height` loss (kept for smaller ones), failing
    /// when they would exceed the adapter's storage binding limit.
    pub fn reserve(&mut self, ctx: &GpuContext, width: u32, height: u32) -> Result<(), LossError> {
        self.reserve_slots(ctx, width, height, 1)
    }

    /// Allocates intermediates for `slots` losses of `width x height` at once.
    fn reserve_slots(
        &mut self,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        slots: u32,
    ) -> Result<(), LossError> {
        let pixels = u64::from(width) * u64::from(height);
        if pixels == 0 {
            return Err(LossError::EmptyImage { width, height });
        }
        let tiles = u64::from(width.div_ceil(LOSS_TILE)) * u64::from(height.div_ceil(LOSS_TILE));
        let slots = u64::from(slots.max(1));
        if self.scratch.as_ref().is_some_and(|scratch| {
            scratch.pixel_capacity >= pixels
                && scratch.tile_capacity >= tiles
                && scratch.slot_capacity >= slots
        }) {
            return Ok(());
        }
        let (pixels, tiles, slots) = match &self.scratch {
            Some(scratch) => (
                pixels.max(scratch.pixel_capacity),
                tiles.max(scratch.tile_capacity),
                slots.max(scratch.slot_capacity),
            ),
            None => (pixels, tiles, slots),
        };
        let storage = |label, size| ctx.storage_buffer(label, size);
        let images = pixels * slots;
        let cells = tiles * CELLS_PER_TILE * slots;
        self.scratch = Some(LossScratch {
            pixel_capacity: pixels,
            tile_capacity: tiles,
            slot_capacity: slots,
            row_moments: storage("loss row moments", images * ROW_MOMENTS_BYTES_PER_PIXEL)?,
            ssim_partials: storage("loss ssim partials", images * PARTIALS_BYTES_PER_PIXEL)?,
            row_partials: storage("loss row partials", images * PARTIALS_BYTES_PER_PIXEL)?,
            loss_partials: storage(
                "loss partial sums",
                tiles * slots * u64::from(PER_PIXEL_INVOCATIONS) * 4,
            )?,
            tile_content: storage("loss cell content", cells * 4)?,
            tile_distance: storage("loss cell distance", cells * 4)?,
            near_items: storage("loss near work items", tiles * slots * 8)?,
            far_items: storage("loss far work items", tiles * slots * 8)?,
            work_counts: ctx.storage_buffer_with_usage(
                "loss work counts",
                std::mem::size_of_val(&EMPTY_WORK_COUNTS) as u64,
                wgpu::BufferUsages::INDIRECT,
            )?,
        });
        Ok(())
    }

    /// How many object losses of `pixels` and `tiles` one set of dispatches computes: as many
    /// as the adapter's binding limit, the scratch budget, the kernels' slot table and the
    /// dispatch size allow (at least one).
    fn slots_per_dispatch(ctx: &GpuContext, pixels: u64, tiles: u64) -> u64 {
        let binding =
            ctx.limits.max_storage_buffer_binding_size / (pixels * ROW_MOMENTS_BYTES_PER_PIXEL);
        let budget = BATCH_SCRATCH_BUDGET_BYTES
            / (pixels * (ROW_MOMENTS_BYTES_PER_PIXEL + 2 * PARTIALS_BYTES_PER_PIXEL));
        let items = u64::from(ctx.limits.max_compute_workgroups_per_dimension) / tiles;
        binding
            .min(budget)
            .min(items)
            .min(u64::from(MAX_BATCH_SLOTS))
            .max(1)
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

    /// Object losses: marks each slot's cells with content, then their distances to it and the
    /// work lists of the four passes.
    #[allow(clippy::too_many_arguments)]
    fn encode_work_lists(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        scratch: &LossScratch,
        bindings: &PassBindings<'_>,
        content: Option<&ObjectContentHints<'_>>,
        [width, height]: [u32; 2],
        slots: u32,
    ) {
        let [tiles_x, tiles_y] = [width.div_ceil(LOSS_TILE), height.div_ceil(LOSS_TILE)];
        match content {
            Some(content) => {
                let [map_0, map_1, map_2] = bindings.id_maps;
                let first = content.cell_maps[0];
                let [cells_0, cells_1, cells_2]: [&wgpu::Buffer; MAX_ID_MAPS] =
                    std::array::from_fn(|index| {
                        content.cell_maps.get(index).copied().unwrap_or(first)
                    });
                let bind = self.cell_content.bind_with(
                    ctx,
                    bindings.params,
                    &[
                        content.occupancy,
                        &scratch.tile_content,
                        map_0,
                        map_1,
                        map_2,
                        cells_0,
                        cells_1,
                        cells_2,
                    ],
                );
                let cells = cell_count(width, height);
                self.cell_content.dispatch(
                    encoder,
                    &bind,
                    [
                        u32::try_from(cells.div_ceil(64)).unwrap_or(u32::MAX),
                        slots,
                        1,
                    ],
                );
            }
            None => {
                encoder.clear_buffer(&scratch.tile_content, 0, None);
                let bind = self.tile_content.bind_with(
                    ctx,
                    bindings.params,
                    &with_inputs(bindings, &[&scratch.tile_content]),
                );
                self.tile_content.dispatch(
                    encoder,
                    &bind,
                    [tiles_x.div_ceil(CONTENT_TILES_PER_GROUP), tiles_y, slots],
                );
            }
        }
        encoder.copy_buffer_to_buffer(
            &self.empty_work_counts,
            0,
            &scratch.work_counts,
            0,
            std::mem::size_of_val(&EMPTY_WORK_COUNTS) as u64,
        );
        let bind = self.work_lists.bind_with(
            ctx,
            bindings.params,
            &[
                &scratch.tile_content,
                &scratch.tile_distance,
                &scratch.work_counts,
                &scratch.near_items,
                &scratch.far_items,
            ],
        );
        self.work_lists
            .dispatch(encoder, &bind, [(tiles_x * tiles_y).div_ceil(64), slots, 1]);
    }

    /// The four SSIM passes and the reduction; `dispatch` launches a pass over every tile or
    /// over its work list (`far`: the last two passes' list).
    fn encode_passes(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        scratch: &LossScratch,
        bindings: &PassBindings<'_>,
        slots: u32,
        dispatch: &dyn Fn(&Kernel, &mut segsplat_gpu::Encoder, &segsplat_gpu::Bound, bool),
    ) {
        let bind = self.moments_horizontal.bind_with(
            ctx,
            bindings.params,
            &with_inputs(
                bindings,
                &[
                    &scratch.row_moments,
                    &scratch.tile_distance,
                    bindings.near_items,
                ],
            ),
        );
        dispatch(&self.moments_horizontal, encoder, &bind, false);
        let bind = self.per_pixel.bind_with(
            ctx,
            bindings.params,
            &with_inputs(
                bindings,
                &[
                    &scratch.row_moments,
                    &scratch.ssim_partials,
                    &scratch.loss_partials,
                    &scratch.tile_distance,
                    bindings.near_items,
                ],
            ),
        );
        dispatch(&self.per_pixel, encoder, &bind, false);
        let bind = self.partials_horizontal.bind_with(
            ctx,
            bindings.params,
            &[
                &scratch.ssim_partials,
                &scratch.row_partials,
                &scratch.tile_distance,
                bindings.far_items,
            ],
        );
        dispatch(&self.partials_horizontal, encoder, &bind, true);
        let bind = self.gradient.bind_with(
            ctx,
            bindings.params,
            &with_inputs(
                bindings,
                &[
                    &scratch.row_partials,
                    bindings.rendered_grad,
                    &scratch.tile_distance,
                    bindings.far_items,
                ],
            ),
        );
        dispatch(&self.gradient, encoder, &bind, true);
        let bind = self.reduce.bind_with(
            ctx,
            bindings.params,
            &[&scratch.loss_partials, bindings.loss_values],
        );
        self.reduce.dispatch(encoder, &bind, [slots, 1, 1]);
    }
}

/// A pass's bindings: the inputs every pass that reads the images binds first (`loss_common.wgsl`,
/// `loss_inputs.wgsl`), then its own.
fn with_inputs<'b>(bindings: &PassBindings<'b>, own: &[&'b wgpu::Buffer]) -> Vec<&'b wgpu::Buffer> {
    let [map_0, map_1, map_2] = bindings.id_maps;
    [bindings.rendered, bindings.target, map_0, map_1, map_2]
        .iter()
        .chain(own)
        .copied()
        .collect()
}

/// The buffers one set of loss dispatches binds, besides its scratch.
struct PassBindings<'a> {
    params: &'a UniformParams,
    rendered: &'a wgpu::Buffer,
    target: &'a wgpu::Buffer,
    id_maps: [&'a wgpu::Buffer; MAX_ID_MAPS],
    near_items: &'a wgpu::Buffer,
    far_items: &'a wgpu::Buffer,
    rendered_grad: &'a wgpu::Buffer,
    loss_values: &'a wgpu::Buffer,
}

/// What one set of loss dispatches computes, as its uniform block says it.
struct LossDispatch<'a> {
    width: u32,
    height: u32,
    use_mask: bool,
    weight: f32,
    first_rendered: u32,
    first_grad: u32,
    first_loss_slot: u32,
    /// The object slots' table rows (empty for an unmasked loss: one slot).
    slots: &'a [[u32; 4]],
}

impl LossDispatch<'_> {
    /// Parameters per set of dispatches, in their own slot of the context's uniform ring (not
    /// queue.write_buffer on a shared buffer), so several losses recorded before one submit each
    /// keep their own.
    fn uniform_params(&self, ctx: &GpuContext) -> UniformParams {
        let tiles_x = self.width.div_ceil(LOSS_TILE);
        let tiles = tiles_x * self.height.div_ceil(LOSS_TILE);
        let mut slots = [[0u32; 4]; MAX_BATCH_SLOTS as usize];
        for (row, slot) in slots.iter_mut().zip(self.slots) {
            *row = *slot;
        }
        let params = LossParams {
            width: self.width,
            height: self.height,
            use_mask: u32::from(self.use_mask),
            slot_count: self.slots.len().max(1) as u32,
            weight: self.weight,
            inv_value_count: (1.0 / (f64::from(self.width) * f64::from(self.height) * 3.0)) as f32,
            first_loss_slot: self.first_loss_slot,
            first_rendered: self.first_rendered,
            first_grad: self.first_grad,
            partial_count: tiles * PER_PIXEL_INVOCATIONS,
            tiles_x,
            padding: 0,
            slots,
        };
        ctx.uniform_params(bytemuck::bytes_of(&params))
    }
}

/// Rejects buffers too small for `slots` losses of the image, which the kernels would otherwise
/// read as zeros.
fn check_sizes(
    images: &LossImages<'_>,
    id_maps: &[&wgpu::Buffer],
    slots: u32,
    outputs: &LossOutputs<'_>,
) -> Result<(), LossError> {
    let (width, height) = (images.width, images.height);
    let pixels = u64::from(width) * u64::from(height);
    if pixels == 0 {
        return Err(LossError::EmptyImage { width, height });
    }
    let slots = u64::from(slots);
    let mut required = vec![
        (
            "rendered image",
            images.rendered,
            (u64::from(images.rendered_index) + slots) * pixels * 16,
        ),
        ("target image", images.target, pixels * 16),
        (
            "rendered gradient",
            outputs.rendered_grad,
            (u64::from(outputs.grad_index) + slots) * pixels * 16,
        ),
        (
            "loss values",
            outputs.loss_values,
            (u64::from(outputs.loss_slot) + slots) * 4,
        ),
    ];
    required.extend(
        id_maps
            .iter()
            .map(|map| ("target object ids", *map, pixels * 4)),
    );
    require_sizes(required, width, height)
}

/// Fails on the first buffer smaller than the bytes a `width x height` loss needs of it.
fn require_sizes<'b>(
    required: impl IntoIterator<Item = (&'static str, &'b wgpu::Buffer, u64)>,
    width: u32,
    height: u32,
) -> Result<(), LossError> {
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

/// Squares of [`SKIP_CELL`] pixels in a `width x height` image.
fn cell_count(width: u32, height: u32) -> u64 {
    u64::from(width.div_ceil(SKIP_CELL)) * u64::from(height.div_ceil(SKIP_CELL))
}

/// Checks a batch's content hints against its images: a cell map per id map, each large enough.
fn check_content_hints(
    images: &ObjectLossImages<'_>,
    content: &ObjectContentHints<'_>,
) -> Result<(), LossError> {
    if content.cell_maps.len() != images.id_maps.len() {
        return Err(LossError::CellMapCount {
            cell_maps: content.cell_maps.len(),
            id_maps: images.id_maps.len(),
        });
    }
    let (width, height) = (images.width, images.height);
    let cell_bytes = cell_count(width, height) * 4;
    let images_needed = u64::from(images.rendered_index) + images.slots.len() as u64;
    let required = std::iter::once((
        "render occupancy",
        content.occupancy,
        images_needed * cell_bytes,
    ))
    .chain(
        content
            .cell_maps
            .iter()
            .map(|map| ("cell map", *map, cell_bytes)),
    );
    require_sizes(required, width, height)
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
