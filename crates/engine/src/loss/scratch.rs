//! The loss's intermediate images, sized for the largest image and batch it has been asked
//! for, and how many object losses fit in one set of dispatches.

use segsplat_gpu::GpuContext;

use super::{
    BATCH_SCRATCH_BUDGET_BYTES, CELLS_PER_TILE, EMPTY_WORK_COUNTS, LOSS_TILE, LossError,
    MAX_BATCH_SLOTS, PARTIALS_BYTES_PER_PIXEL, PER_PIXEL_INVOCATIONS, ROW_MOMENTS_BYTES_PER_PIXEL,
    RenderLoss,
};

/// Intermediate images for up to `slot_capacity` losses of one image size; grown, never shrunk.
#[derive(Debug)]
pub(super) struct LossScratch {
    /// Per slot.
    pub(super) pixel_capacity: u64,
    /// Per slot: workgroups of the per-pixel kernel, one loss partial sum per invocation each.
    pub(super) tile_capacity: u64,
    pub(super) slot_capacity: u64,
    pub(super) row_moments: wgpu::Buffer,
    pub(super) ssim_partials: wgpu::Buffer,
    pub(super) row_partials: wgpu::Buffer,
    pub(super) loss_partials: wgpu::Buffer,
    /// Per slot and skip cell: content flag, then distance in cells to content (object losses).
    pub(super) tile_content: wgpu::Buffer,
    pub(super) tile_distance: wgpu::Buffer,
    /// (slot, tile) pairs within reach 1 and 2 of content, and their dispatch arguments.
    pub(super) near_items: wgpu::Buffer,
    pub(super) far_items: wgpu::Buffer,
    pub(super) work_counts: wgpu::Buffer,
}

impl RenderLoss {
    /// Allocates intermediates for one `width x height` loss (kept for smaller ones), failing
    /// when they would exceed the adapter's storage binding limit.
    pub fn reserve(&mut self, ctx: &GpuContext, width: u32, height: u32) -> Result<(), LossError> {
        self.reserve_slots(ctx, width, height, 1)
    }

    /// Allocates intermediates for `slots` losses of `width x height` at once.
    pub(super) fn reserve_slots(
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
    pub(super) fn slots_per_dispatch(ctx: &GpuContext, pixels: u64, tiles: u64) -> u64 {
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
}
