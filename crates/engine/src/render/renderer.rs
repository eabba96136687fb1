//! [`Renderer`]: records forward and backward passes into the caller's command encoder.

use std::sync::Arc;

use super::capacity::PEAK_WORDS;
use super::kernels::{RasterVariant, RenderKernels};
use super::output::{RenderError, RenderOutput};
use super::uniforms::RenderUniforms;
use super::workspace::{
    COUNT_SLOTS, INTERSECTION_COUNT_OFFSET, INTERSECTION_DISPATCH_OFFSET, RenderWorkspace,
    WorkspacePool, WorkspaceSize,
};
use crate::model::GaussianView;
use crate::{GpuGaussianGrads, RenderCamera, RenderSettings};
use segsplat_gpu::deferred_read::DeferredRead;
use segsplat_gpu::kernel::{workgroups_2d, workgroups_for};
use segsplat_gpu::sort::RadixSort;
use segsplat_gpu::{ExclusiveScan, GpuContext};

/// Initial intersections per Gaussian before any peak is known.
const INITIAL_INTERSECTIONS_PER_GAUSSIAN: usize = 8;
const MIN_INTERSECTION_CAPACITY: u32 = 1 << 16;
/// Renders [`Renderer::render_checked`] tries before giving up.
pub(crate) const RENDER_ATTEMPTS: usize = 3;

/// Records Gaussian-splat renders. One per device; cheap to keep for the process lifetime.
///
/// Capacity policy for tile intersections: the intersection buffers hold `capacity` entries
/// (initially `max(65536, 8 x Gaussians)`, never above one storage binding). Every forward pass
/// clamps its count to its capacity on the GPU (excess entries are dropped, never written out of
/// bounds), folds its unclamped count into a running peak on the GPU and counts itself when it
/// was clamped. The caller reads both lazily with [`Renderer::sync_capacity`] (one-off renders:
/// [`Renderer::render_checked`]; the training loop every few dozen steps without waiting,
/// [`Renderer::request_capacity_check`]), which grows the capacity to 1.5x the peak once the
/// peak passes 80% and reports whether any render overflowed; the clamped renders that were used
/// add up in [`Renderer::clamped_renders`], so an overflow is never silent.
pub struct Renderer {
    pub(super) kernels: RenderKernels,
    pub(super) scan: ExclusiveScan,
    pub(super) sort: RadixSort,
    pub(super) pool: Arc<WorkspacePool>,
    /// [`PEAK_WORDS`]: the running maximum of unclamped intersection counts since the last
    /// read, and how many renders were ever clamped to their capacity.
    pub(super) peak_intersections: wgpu::Buffer,
    pub(super) intersection_capacity: u32,
    /// Smallest capacity any render used since the last sync.
    pub(super) smallest_capacity_used: Option<u32>,
    /// The peak's deferred read-back for loops that must not wait ([`Self::request_capacity_check`]).
    pub(super) peak_read: DeferredRead,
    /// Renders clamped to their capacity whose output was used (not rendered again), since
    /// this renderer was made: each dropped tile entries, so its image and gradients were
    /// approximate ([`Self::clamped_renders`]).
    pub(super) clamped_renders: u64,
    /// The newest count of clamped renders read from the GPU (its second word).
    pub(super) clamped_read: u32,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("intersection_capacity", &self.intersection_capacity)
            .finish_non_exhaustive()
    }
}

impl Renderer {
    pub fn new(ctx: &GpuContext) -> Result<Self, RenderError> {
        Self::with_variant(ctx, RasterVariant::for_adapter(ctx))
    }

    /// [`Self::new`] with chosen rasterize kernels rather than the adapter's (tests check each).
    pub fn with_variant(ctx: &GpuContext, variant: RasterVariant) -> Result<Self, RenderError> {
        Ok(Self {
            kernels: RenderKernels::new(ctx, variant)?,
            scan: ExclusiveScan::new(ctx)?,
            sort: RadixSort::new(ctx)?,
            pool: Arc::new(WorkspacePool::default()),
            peak_intersections: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("peak intersections"),
                size: PEAK_WORDS * 4,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            intersection_capacity: MIN_INTERSECTION_CAPACITY,
            smallest_capacity_used: None,
            peak_read: DeferredRead::new(ctx, "peak intersections read-back", PEAK_WORDS * 4),
            clamped_renders: 0,
            clamped_read: 0,
        })
    }

    /// Current intersection capacity.
    pub fn intersection_capacity(&self) -> u32 {
        self.intersection_capacity
    }

    /// Renders whose intersections were clamped to the capacity and which were used as they
    /// were (training steps between two capacity checks), as far as the reads so far know: the
    /// count a run reports so that approximate steps are never silent.
    pub fn clamped_renders(&self) -> u64 {
        self.clamped_renders
    }

    /// Sets the intersection capacity (e.g. restored from a previous run).
    pub fn set_intersection_capacity(&mut self, capacity: u32) {
        self.intersection_capacity = capacity.max(1);
        self.pool.retire_smaller_than(self.intersection_capacity);
    }

    pub(super) fn max_intersections(ctx: &GpuContext) -> u64 {
        ctx.limits.max_storage_buffer_binding_size / 4
    }

    /// Records a forward pass. The returned output holds the image (valid once the encoder is
    /// submitted) and the state [`Renderer::backward`] needs.
    pub fn forward<'g>(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        gaussians: impl Into<GaussianView<'g>>,
        camera: &RenderCamera,
        settings: &RenderSettings,
    ) -> Result<RenderOutput, RenderError> {
        if camera.width == 0 || camera.height == 0 {
            return Err(RenderError::EmptyImage {
                width: camera.width,
                height: camera.height,
            });
        }
        let gaussians: GaussianView<'_> = gaussians.into();
        let count = gaussians.count;
        let [tiles_x, tiles_y] = camera.tile_grid();
        let workspace = self.take_workspace(
            ctx,
            gaussians,
            camera.pixel_count(),
            (tiles_x * tiles_y) as usize,
        )?;
        let workspace_capacity = workspace.size.intersections;
        let uniforms = RenderUniforms::new(camera, settings, count as u32, workspace_capacity);
        self.upload_uniforms(ctx, encoder, &workspace, &uniforms);
        encoder.clear_buffer(&workspace.tile_ranges, 0, None);
        if count > 0 {
            self.encode_tiles(
                ctx,
                encoder,
                gaussians,
                &workspace,
                count as u32,
                [tiles_x, tiles_y],
            );
        }
        let k = &self.kernels;
        let rasterize = k.rasterize_forward.bind(
            ctx,
            &[
                &workspace.uniforms,
                &workspace.tile_ranges,
                &workspace.intersection_gaussians,
                &workspace.projected,
                &workspace.image,
                &workspace.final_transmittance,
                &workspace.last_contributor,
                &workspace.depth,
                &workspace.occupancy,
            ],
        );
        k.rasterize_forward
            .dispatch(encoder, &rasterize, [tiles_x, tiles_y, 1]);
        Ok(RenderOutput {
            workspace: Some(workspace),
            pool: Arc::clone(&self.pool),
            camera: *camera,
            settings: *settings,
            gaussian_count: count as u32,
        })
    }

    /// A pooled workspace for a render of `gaussians` over `pixels` and `tiles` (all slots of a
    /// batched render), with the current intersection capacity, recorded for the next sync.
    pub(super) fn take_workspace(
        &mut self,
        ctx: &GpuContext,
        gaussians: GaussianView<'_>,
        pixels: usize,
        tiles: usize,
    ) -> Result<RenderWorkspace, RenderError> {
        let limit = Self::max_intersections(ctx);
        let wanted = (gaussians.count * INITIAL_INTERSECTIONS_PER_GAUSSIAN) as u64;
        let capacity = (self.intersection_capacity as u64)
            .max(wanted)
            .min(limit)
            .min(u32::MAX as u64) as u32;
        self.intersection_capacity = capacity;
        let size = WorkspaceSize {
            gaussians: gaussians.capacity.max(1),
            pixels,
            tiles,
            intersections: capacity,
        };
        let workspace = self.pool.take(ctx, size)?;
        let workspace_capacity = workspace.size.intersections;
        self.smallest_capacity_used = Some(
            self.smallest_capacity_used
                .map_or(workspace_capacity, |c| c.min(workspace_capacity)),
        );
        Ok(workspace)
    }

    /// Writes the uniforms and the Gaussian count through the encoder (not `queue.write_buffer`),
    /// so several renders recorded into one encoder each see their own values; the bytes come
    /// from the context's uniform ring, not a staging buffer per render.
    pub(super) fn upload_uniforms(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        workspace: &RenderWorkspace,
        uniforms: &RenderUniforms,
    ) {
        let mut counts = [0u32; COUNT_SLOTS];
        counts[0] = uniforms.gaussian_count;
        ctx.encode_upload(
            encoder,
            bytemuck::bytes_of(uniforms),
            &workspace.uniforms,
            0,
        );
        ctx.encode_upload(encoder, bytemuck::cast_slice(&counts), &workspace.counts, 0);
    }

    /// Steps 1-8 of the module doc: projection to per-tile depth-ordered ranges.
    fn encode_tiles(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        gaussians: GaussianView<'_>,
        workspace: &RenderWorkspace,
        count: u32,
        [tiles_x, tiles_y]: [u32; 2],
    ) {
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension;
        let per_gaussian = workgroups_2d(workgroups_for(count, 256), max_groups);
        let k = &self.kernels;
        let p = gaussians;
        let project = k.project_forward.bind(
            ctx,
            &[
                &workspace.uniforms,
                p.means,
                p.log_scales,
                p.rotations,
                p.opacity_logits,
                p.sh_dc,
                p.sh_rest[0],
                p.sh_rest[1],
                p.sh_rest[2],
                gaussians.object_ids,
                &workspace.projected,
                &workspace.tile_counts,
                &workspace.depth_keys,
                &workspace.depth_values,
            ],
        );
        k.project_forward.dispatch(encoder, &project, per_gaussian);
        self.sort.encode(
            ctx,
            encoder,
            &workspace.depth_keys,
            &workspace.depth_values,
            &workspace.counts,
            0,
            count,
            32,
        );
        let k = &self.kernels;
        let gather = k.tile_count_in_depth_order.bind(
            ctx,
            &[
                &workspace.uniforms,
                &workspace.depth_values,
                &workspace.tile_counts,
                &workspace.tile_counts_in_depth_order,
            ],
        );
        k.tile_count_in_depth_order
            .dispatch(encoder, &gather, per_gaussian);
        self.scan.encode(
            ctx,
            encoder,
            &workspace.tile_counts_in_depth_order,
            &workspace.tile_offsets,
            count,
        );
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
        let emit = k.tile_emit.bind(
            ctx,
            &[
                &workspace.uniforms,
                &workspace.depth_values,
                &workspace.tile_offsets,
                &workspace.projected,
                &workspace.intersection_tiles,
                &workspace.intersection_gaussians,
            ],
        );
        k.tile_emit.dispatch(encoder, &emit, per_gaussian);
        self.encode_tile_ranges(ctx, encoder, workspace, tiles_x * tiles_y);
    }

    /// Steps 7-8 of the module doc: sorts the emitted (key, Gaussian) pairs stably by key
    /// (`key_count` distinct keys: tiles, or (slot, tile) for an object batch) and writes each
    /// key's range.
    pub(super) fn encode_tile_ranges(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        workspace: &RenderWorkspace,
        key_count: u32,
    ) {
        let key_bits = (u32::BITS - (key_count.max(2) - 1).leading_zeros()).max(1);
        self.sort.encode(
            ctx,
            encoder,
            &workspace.intersection_tiles,
            &workspace.intersection_gaussians,
            &workspace.counts,
            INTERSECTION_COUNT_OFFSET,
            workspace.size.intersections,
            key_bits,
        );
        let k = &self.kernels;
        let ranges = k.tile_ranges.bind(
            ctx,
            &[
                &workspace.counts,
                &workspace.intersection_tiles,
                &workspace.tile_ranges,
            ],
        );
        k.tile_ranges.dispatch_indirect(
            encoder,
            &ranges,
            &workspace.counts,
            INTERSECTION_DISPATCH_OFFSET,
        );
    }

    /// Records the backward pass of `output` given `grad_image` (d loss / d image, the image's
    /// layout: `width * height` vec4 of d/d(r, g, b, alpha)). ADDS parameter gradients and the
    /// |d mean2d| statistic into `grads`; zero them once per step, not per render.
    /// [`Self::backward_screen`] then [`Self::backward_projection`], for a render alone.
    pub fn backward<'g>(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        gaussians: impl Into<GaussianView<'g>>,
        output: &RenderOutput,
        grad_image: &wgpu::Buffer,
        grads: &mut GpuGaussianGrads,
    ) -> Result<(), RenderError> {
        self.backward_screen(ctx, encoder, output, grad_image)?;
        self.backward_projection(ctx, encoder, gaussians, output, grads)
    }

    /// The first half of [`Self::backward`]: `output`'s screen-space gradients (per projected
    /// splat), overwriting those of an earlier backward of it. Object renders batched on
    /// `output` add theirs on top ([`Self::backward_objects_screen`]) before the one
    /// [`Self::backward_projection`] that all of them share.
    pub fn backward_screen(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        output: &RenderOutput,
        grad_image: &wgpu::Buffer,
    ) -> Result<(), RenderError> {
        if grad_image.size() < output.image_bytes() {
            return Err(RenderError::GradImageTooSmall {
                bytes: grad_image.size(),
                needed: output.image_bytes(),
                pixels: output.camera.pixel_count(),
            });
        }
        if output.gaussian_count == 0 {
            return Ok(());
        }
        let workspace = output.workspace();
        encoder.clear_buffer(&workspace.grad_projected, 0, None);
        let k = &self.kernels;
        let [tiles_x, tiles_y] = output.camera.tile_grid();
        let rasterize = k.rasterize_backward.bind(
            ctx,
            &[
                &workspace.uniforms,
                &workspace.tile_ranges,
                &workspace.intersection_gaussians,
                &workspace.projected,
                &workspace.final_transmittance,
                &workspace.last_contributor,
                grad_image,
                &workspace.grad_projected,
            ],
        );
        k.rasterize_backward
            .dispatch(encoder, &rasterize, [tiles_x, tiles_y, 1]);
        Ok(())
    }

    /// The second half of [`Self::backward`]: the projection's backward from `output`'s
    /// screen-space gradients (its own and those of any object renders batched on it), ADDING
    /// into `grads`.
    pub fn backward_projection<'g>(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        gaussians: impl Into<GaussianView<'g>>,
        output: &RenderOutput,
        grads: &mut GpuGaussianGrads,
    ) -> Result<(), RenderError> {
        let count = output.gaussian_count as usize;
        if grads.capacity() < count {
            return Err(RenderError::GradsTooSmall {
                count,
                capacity: grads.capacity(),
            });
        }
        if count == 0 {
            return Ok(());
        }
        self.encode_projection_backward(
            ctx,
            encoder,
            gaussians.into(),
            output.workspace(),
            count as u32,
            grads,
        );
        Ok(())
    }

    /// The backward of the projection (geometry, then colour) from `workspace.grad_projected`,
    /// adding into `grads`. Runs once per set of rasterize backwards that share the projection.
    fn encode_projection_backward(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        gaussians: GaussianView<'_>,
        workspace: &RenderWorkspace,
        count: u32,
        grads: &mut GpuGaussianGrads,
    ) {
        let k = &self.kernels;
        let per_gaussian = workgroups_2d(
            workgroups_for(count, 256),
            ctx.limits.max_compute_workgroups_per_dimension,
        );
        let p = gaussians;
        let g = &grads.parameters;
        let geometry = k.project_backward.bind(
            ctx,
            &[
                &workspace.uniforms,
                p.means,
                p.log_scales,
                p.rotations,
                &workspace.projected,
                &workspace.grad_projected,
                &g.means,
                &g.log_scales,
                &g.rotations,
                &g.opacity_logits,
                &grads.mean2d_abs,
            ],
        );
        k.project_backward
            .dispatch(encoder, &geometry, per_gaussian);
        let colour = k.sh_backward.bind(
            ctx,
            &[
                &workspace.uniforms,
                p.means,
                p.sh_dc,
                p.sh_rest[0],
                p.sh_rest[1],
                p.sh_rest[2],
                &workspace.projected,
                &workspace.grad_projected,
                &g.means,
                &g.sh_dc,
                &g.sh_rest[0],
                &g.sh_rest[1],
                &g.sh_rest[2],
            ],
        );
        k.sh_backward.dispatch(encoder, &colour, per_gaussian);
    }

    /// Multiplies the intersection capacity by `factor` (within one storage binding), for a
    /// caller that knows its next renders need more (a finer training resolution).
    pub fn grow_intersection_capacity(&mut self, ctx: &GpuContext, factor: f64) {
        let grown = (self.intersection_capacity as f64 * factor).ceil();
        let limit = Self::max_intersections(ctx).min(u32::MAX as u64) as f64;
        self.set_intersection_capacity(grown.min(limit).max(1.0) as u32);
    }

    /// Renders now (own encoder, submitted), re-rendering with grown buffers when the first
    /// attempt overflowed: for one-off renders (masks, evaluation, tests).
    pub fn render_checked<'g>(
        &mut self,
        ctx: &GpuContext,
        gaussians: impl Into<GaussianView<'g>>,
        camera: &RenderCamera,
        settings: &RenderSettings,
    ) -> Result<RenderOutput, RenderError> {
        let gaussians: GaussianView<'_> = gaussians.into();
        // A pending sync from earlier renders must not be mistaken for this render's (theirs
        // were used: counted).
        self.sync_capacity(ctx)?;
        // Each retry grows the capacity to 1.5x the needed count, so the second attempt fits
        // unless the scene exceeds the adapter (an error from sync_capacity).
        for _ in 0..RENDER_ATTEMPTS {
            let mut encoder = segsplat_gpu::Encoder::new(ctx, "render");
            let output = self.forward(ctx, &mut encoder, gaussians, camera, settings)?;
            ctx.submit_untimed(encoder.finish());
            let report = self.sync_capacity_to_retry(ctx)?;
            if !report.overflowed {
                return Ok(output);
            }
        }
        Err(RenderError::CapacityNotConverging {
            attempts: RENDER_ATTEMPTS,
        })
    }
}
