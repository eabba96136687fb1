//! The dispatches of one set of losses: the object losses' work lists, the four SSIM passes and
//! the reduction, with the uniform block they share.

use segsplat_gpu::{GpuContext, Kernel, UniformParams};

use super::checks::cell_count;
use super::scratch::LossScratch;
use super::{
    CONTENT_TILES_PER_GROUP, EMPTY_WORK_COUNTS, LOSS_TILE, MAX_BATCH_SLOTS, MAX_ID_MAPS,
    ObjectContentHints, PER_PIXEL_INVOCATIONS, RenderLoss,
};

/// Uniform block of `loss_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct LossParams {
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

impl RenderLoss {
    /// Object losses: marks each slot's cells with content, then their distances to it and the
    /// work lists of the four passes.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn encode_work_lists(
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
    pub(super) fn encode_passes(
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
pub(super) fn with_inputs<'b>(
    bindings: &PassBindings<'b>,
    own: &[&'b wgpu::Buffer],
) -> Vec<&'b wgpu::Buffer> {
    let [map_0, map_1, map_2] = bindings.id_maps;
    [bindings.rendered, bindings.target, map_0, map_1, map_2]
        .iter()
        .chain(own)
        .copied()
        .collect()
}

/// The buffers one set of loss dispatches binds, besides its scratch.
pub(super) struct PassBindings<'a> {
    pub(super) params: &'a UniformParams,
    pub(super) rendered: &'a wgpu::Buffer,
    pub(super) target: &'a wgpu::Buffer,
    pub(super) id_maps: [&'a wgpu::Buffer; MAX_ID_MAPS],
    pub(super) near_items: &'a wgpu::Buffer,
    pub(super) far_items: &'a wgpu::Buffer,
    pub(super) rendered_grad: &'a wgpu::Buffer,
    pub(super) loss_values: &'a wgpu::Buffer,
}

/// What one set of loss dispatches computes, as its uniform block says it.
pub(super) struct LossDispatch<'a> {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) use_mask: bool,
    pub(super) weight: f32,
    pub(super) first_rendered: u32,
    pub(super) first_grad: u32,
    pub(super) first_loss_slot: u32,
    /// The object slots' table rows (empty for an unmasked loss: one slot).
    pub(super) slots: &'a [[u32; 4]],
}

impl LossDispatch<'_> {
    /// Parameters per set of dispatches, in their own slot of the context's uniform ring (not
    /// queue.write_buffer on a shared buffer), so several losses recorded before one submit each
    /// keep their own.
    pub(super) fn uniform_params(&self, ctx: &GpuContext) -> UniformParams {
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
