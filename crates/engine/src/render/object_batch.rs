//! Batched object renders: every object render of one camera (the Segment-then-Splat object
//! loss, the partial-mask filter) recorded as one set of dispatches on top of the camera's full
//! render.
//!
//! An object render is the full render with every other object's Gaussians culled, so the
//! projection, the SH colours and the depth order of the full render serve every object of the
//! same camera. On top of them a batch of `k` object slots (each a (level, id)) costs:
//!
//! | step | kernel                         | work                                                 |
//! |------|--------------------------------|------------------------------------------------------|
//! | 1    | `object_tile_count.wgsl`        | per Gaussian in depth order: tiles x slots it is in  |
//! | 2    | exclusive scan                 | intersection offsets                                 |
//! | 3    | `tile_budget.wgsl`              | clamp to capacity (shared capacity policy)           |
//! | 4    | `object_tile_emit.wgsl`         | (slot x tiles + tile, Gaussian) in depth order       |
//! | 5    | radix sort (stable)            | by (slot, tile): depth order within each             |
//! | 6    | `tile_ranges.wgsl`              | each (slot, tile)'s [start, end)                      |
//! | 7    | rasterize forward, z = slot    | slot s's image at pixels [s P, (s + 1) P)            |
//!
//! Each slot costs only its own footprint. The backward is one rasterize backward over all slots
//! (z = slot) adding into the full render's screen-space gradients, after the full render's own,
//! then one projection and SH backward for the full render and every slot together: the loss is
//! a sum over renders and all of them share the projected parameters, so summing the
//! screen-space gradients first is exact (up to float atomics' order).

use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::output::{RenderError, RenderOutput};
use super::renderer::Renderer;
use super::uniforms::RenderUniforms;
use super::workspace::{RenderWorkspace, SLOT_TABLE_CAPACITY, WorkspacePool};
use crate::model::GaussianView;
use crate::{ObjectFilter, RenderCamera, RenderSettings};
use segsplat_gpu::kernel::{workgroups_2d, workgroups_for};
use segsplat_gpu::{Binding, GpuContext, GpuError};
use segsplat_scene::Level;

/// One object of a batch: the Gaussians whose id at `level` is `id`, rendered alone on black.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectSlot {
    pub level: Level,
    pub id: u32,
}

impl ObjectSlot {
    /// The filter a separate render of this object uses (the reference the batch must match).
    pub fn filter(&self) -> ObjectFilter {
        ObjectFilter::Object {
            level: self.level,
            id: self.id,
        }
    }
}

/// The object renders of one batch: slot `s`'s image is pixels `[s P, (s + 1) P)` of
/// [`ObjectBatchOutput::images`]. Borrows the full render it builds on (its projection stays in
/// use until the batch's backward). Dropping it returns its buffers to the renderer's pool.
#[derive(Debug)]
pub struct ObjectBatchOutput<'b> {
    base: &'b RenderOutput,
    workspace: Option<RenderWorkspace>,
    pool: Arc<WorkspacePool>,
    pub camera: RenderCamera,
    pub slots: Vec<ObjectSlot>,
    pub gaussian_count: u32,
    /// The slots as the kernels read them (see [`slot_table`]).
    slot_table: wgpu::Buffer,
}

impl Drop for ObjectBatchOutput<'_> {
    fn drop(&mut self) {
        if let Some(workspace) = self.workspace.take() {
            self.pool.give_back(workspace);
        }
    }
}

impl ObjectBatchOutput<'_> {
    /// The batch's slots as the kernels read them.
    pub fn slot_table(&self) -> &wgpu::Buffer {
        &self.slot_table
    }

    fn workspace(&self) -> &RenderWorkspace {
        // Only `drop` takes the workspace out.
        self.workspace
            .as_ref()
            .unwrap_or_else(|| unreachable!("workspace present until drop"))
    }

    /// Every slot's image, `array<vec4<f32>>` (rgb, alpha; black background), slot after slot.
    pub fn images(&self) -> &wgpu::Buffer {
        &self.workspace().image
    }

    /// Which squares of each slot's image hold a non-zero colour: a u32 per
    /// [`crate::OCCUPANCY_CELL`] square, 1 or 0, `ceil(width / OCCUPANCY_CELL)` squares across
    /// and `ceil(height / OCCUPANCY_CELL)` down, row-major, slot after slot. An object render
    /// usually covers a small part of the image; the object loss skips what is exactly zero.
    pub fn occupancy(&self) -> &wgpu::Buffer {
        &self.workspace().occupancy
    }

    /// Bytes of one slot's image (the byte offset of slot `s` is `s` times this).
    pub fn slot_image_bytes(&self) -> u64 {
        self.camera.pixel_count() as u64 * 16
    }

    /// Reads every slot's image back (tests, the partial-mask filter; never inside a step).
    pub fn read_images(&self, ctx: &GpuContext) -> Result<Vec<Vec<[f32; 4]>>, GpuError> {
        let bytes = ctx.read_buffer(
            self.images(),
            self.slot_image_bytes() * self.slots.len() as u64,
        )?;
        let pixels: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(pixels
            .chunks(self.camera.pixel_count())
            .map(<[[f32; 4]]>::to_vec)
            .collect())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ObjectBatchError {
    #[error("a batch of object renders needs at least one object slot")]
    NoSlots,
    #[error("object renders reuse a full render's projection; this one is filtered ({0:?})")]
    BaseFiltered(ObjectFilter),
    #[error("the full render has {base} Gaussians but the scene has {scene}")]
    SceneChanged { base: u32, scene: usize },
}

impl Renderer {
    /// Records the renders of `slots` (each its object alone, on black) for `base`'s camera,
    /// reusing `base`'s projection, colours and depth order. `base` must be an unfiltered
    /// forward pass of the same `gaussians`, recorded earlier into this encoder or submitted.
    pub fn forward_objects<'g, 'b>(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        gaussians: impl Into<GaussianView<'g>>,
        base: &'b RenderOutput,
        slots: &[ObjectSlot],
    ) -> Result<ObjectBatchOutput<'b>, RenderError> {
        let gaussians: GaussianView<'_> = gaussians.into();
        check_batch(base, gaussians, slots)?;
        let camera = base.camera;
        let count = base.gaussian_count;
        let k = slots.len() as u32;
        let [tiles_x, tiles_y] = camera.tile_grid();
        let tiles_per_slot = tiles_x * tiles_y;
        let workspace = self.take_workspace(
            ctx,
            gaussians,
            camera.pixel_count() * slots.len(),
            (tiles_per_slot * k) as usize,
        )?;
        let settings = RenderSettings {
            filter: ObjectFilter::All,
            background: [0.0; 3],
            sh_degree: base.settings.sh_degree,
        };
        let mut uniforms =
            RenderUniforms::new(&camera, &settings, count, workspace.size.intersections);
        // Object renders do not feed the densification statistic (backward_objects_screen).
        uniforms.mean2d_abs = 0;
        uniforms.mark_occupancy = 1;
        self.upload_uniforms(ctx, encoder, &workspace, &uniforms);
        let slot_table = upload_slot_table(ctx, encoder, &workspace, slots);
        encoder.clear_buffer(&workspace.tile_ranges, 0, None);
        encoder.clear_buffer(&workspace.occupancy, 0, None);
        if count > 0 {
            self.encode_object_tiles(
                ctx,
                encoder,
                gaussians,
                base,
                &workspace,
                &slot_table,
                slots.len() as u32,
                tiles_per_slot,
            );
        }
        let shared = base.workspace();
        let kernels = &self.kernels;
        let rasterize = kernels.rasterize_forward.bind(
            ctx,
            &[
                &workspace.uniforms,
                &workspace.tile_ranges,
                &workspace.intersection_gaussians,
                &shared.projected,
                &workspace.image,
                &workspace.final_transmittance,
                &workspace.last_contributor,
                &workspace.depth,
                &workspace.occupancy,
            ],
        );
        kernels
            .rasterize_forward
            .dispatch(encoder, &rasterize, [tiles_x, tiles_y, k]);
        Ok(ObjectBatchOutput {
            base,
            workspace: Some(workspace),
            pool: Arc::clone(&self.pool),
            camera,
            slots: slots.to_vec(),
            gaussian_count: count,
            slot_table,
        })
    }

    /// Steps 1-6 of the module doc.
    #[allow(clippy::too_many_arguments)]
    fn encode_object_tiles(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        gaussians: GaussianView<'_>,
        base: &RenderOutput,
        workspace: &RenderWorkspace,
        slot_table: &wgpu::Buffer,
        slot_count: u32,
        tiles_per_slot: u32,
    ) {
        let count = base.gaussian_count;
        let shared = base.workspace();
        let per_gaussian = workgroups_2d(
            workgroups_for(count, 256),
            ctx.limits.max_compute_workgroups_per_dimension,
        );
        let k = &self.kernels;
        // Exactly the batch's slots: the kernels loop to the binding's `arrayLength`.
        let slots = Binding::Range {
            buffer: slot_table,
            offset: 0,
            size: u64::from(slot_count) * 8,
        };
        let tally = k.object_tile_count.bind_entries(
            ctx,
            &[
                Binding::Whole(&workspace.uniforms),
                Binding::Whole(&shared.depth_values),
                Binding::Whole(&shared.tile_counts),
                Binding::Whole(gaussians.object_ids),
                slots,
                Binding::Whole(&workspace.tile_counts_in_depth_order),
            ],
        );
        k.object_tile_count.dispatch(encoder, &tally, per_gaussian);
        self.scan.encode(
            ctx,
            encoder,
            &workspace.tile_counts_in_depth_order,
            &workspace.tile_offsets,
            count,
        );
        let k = &self.kernels;
        let budget = k.tile_budget.bind(
            ctx,
            &[
                &workspace.uniforms,
                &workspace.tile_offsets,
                &workspace.counts,
                &self.peak_intersections,
            ],
        );
        k.tile_budget.dispatch(encoder, &budget, [1, 1, 1]);
        let emit = k.object_tile_emit.bind_entries(
            ctx,
            &[
                Binding::Whole(&workspace.uniforms),
                Binding::Whole(&shared.depth_values),
                Binding::Whole(&workspace.tile_offsets),
                Binding::Whole(&shared.tile_counts),
                Binding::Whole(gaussians.object_ids),
                slots,
                Binding::Whole(&shared.projected),
                Binding::Whole(&workspace.intersection_tiles),
                Binding::Whole(&workspace.intersection_gaussians),
            ],
        );
        k.object_tile_emit.dispatch(encoder, &emit, per_gaussian);
        self.encode_tile_ranges(ctx, encoder, workspace, tiles_per_slot * slot_count);
    }

    /// Records the backward of every slot of `batch` given `grad_images` (d loss / d image, slot
    /// after slot, as [`ObjectBatchOutput::images`]), ADDING the slots' screen-space gradients
    /// to those of the full render it is batched on: record that render's
    /// [`Renderer::backward_screen`] before this and its [`Renderer::backward_projection`]
    /// after, once for all of them. The slots add nothing to the |d mean2d| statistic, which
    /// densification takes from the full render's loss alone (as the released code does).
    pub fn backward_objects_screen(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        batch: &ObjectBatchOutput<'_>,
        grad_images: &wgpu::Buffer,
    ) -> Result<(), RenderError> {
        let needed = batch.slot_image_bytes() * batch.slots.len() as u64;
        if grad_images.size() < needed {
            return Err(RenderError::GradImageTooSmall {
                bytes: grad_images.size(),
                needed,
                pixels: batch.camera.pixel_count() * batch.slots.len(),
            });
        }
        if batch.gaussian_count == 0 {
            return Ok(());
        }
        let shared = batch.base.workspace();
        let workspace = batch.workspace();
        let [tiles_x, tiles_y] = batch.camera.tile_grid();
        let k = &self.kernels;
        let rasterize = k.rasterize_backward.bind(
            ctx,
            &[
                &workspace.uniforms,
                &workspace.tile_ranges,
                &workspace.intersection_gaussians,
                &shared.projected,
                &workspace.final_transmittance,
                &workspace.last_contributor,
                grad_images,
                &shared.grad_projected,
            ],
        );
        k.rasterize_backward.dispatch(
            encoder,
            &rasterize,
            [tiles_x, tiles_y, batch.slots.len() as u32],
        );
        Ok(())
    }
}

/// The slots in the workspace's table, written through the encoder (no buffer per batch), or
/// in a table of their own past [`SLOT_TABLE_CAPACITY`].
fn upload_slot_table(
    ctx: &GpuContext,
    encoder: &mut segsplat_gpu::Encoder,
    workspace: &RenderWorkspace,
    slots: &[ObjectSlot],
) -> wgpu::Buffer {
    if slots.len() > SLOT_TABLE_CAPACITY {
        ctx.count_buffer_created();
        return slot_table(ctx, slots);
    }
    let table = slot_words(slots);
    ctx.encode_upload(
        encoder,
        bytemuck::cast_slice(&table),
        &workspace.slot_table,
        0,
    );
    workspace.slot_table.clone()
}

fn slot_words(slots: &[ObjectSlot]) -> Vec<[u32; 2]> {
    slots
        .iter()
        .map(|slot| [slot.level.index() as u32, slot.id])
        .collect()
}

/// The slots as the kernels read them: `array<vec2<u32>>` of (level index, id).
pub fn slot_table(ctx: &GpuContext, slots: &[ObjectSlot]) -> wgpu::Buffer {
    let table = slot_words(slots);
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("object slots"),
            contents: bytemuck::cast_slice(&table),
            usage: wgpu::BufferUsages::STORAGE,
        })
}

fn check_batch(
    base: &RenderOutput,
    gaussians: GaussianView<'_>,
    slots: &[ObjectSlot],
) -> Result<(), ObjectBatchError> {
    if slots.is_empty() {
        return Err(ObjectBatchError::NoSlots);
    }
    if base.settings.filter != ObjectFilter::All {
        return Err(ObjectBatchError::BaseFiltered(base.settings.filter));
    }
    if gaussians.count != base.gaussian_count as usize {
        return Err(ObjectBatchError::SceneChanged {
            base: base.gaussian_count,
            scene: gaussians.count,
        });
    }
    Ok(())
}
