//! The buffers one render uses, pooled so steady-state training allocates nothing per frame.

use segsplat_gpu::{GpuContext, GpuError};

/// Floats of per-Gaussian screen-space gradient (`GRAD_STRIDE` in `project_common.wgsl`).
pub const GRAD_STRIDE: usize = 12;
/// u32 slots of the `counts` buffer (see `tile_budget.wgsl`).
pub const COUNT_SLOTS: usize = 8;
/// Byte offset of the clamped intersection count in `counts`.
pub const INTERSECTION_COUNT_OFFSET: u64 = 4;
/// Byte offset of the per-intersection indirect dispatch size in `counts`.
pub const INTERSECTION_DISPATCH_OFFSET: u64 = 8;

/// Occupancy squares per tile: a tile's side spans `TILE_SIZE / OCCUPANCY_CELL` of them, and an
/// image's last (partial) square in a row or column lies in its last tile.
const OCCUPANCY_CELLS_PER_TILE: usize = (crate::TILE_SIZE / crate::OCCUPANCY_CELL
    * (crate::TILE_SIZE / crate::OCCUPANCY_CELL)) as usize;

/// Sizes a workspace is allocated for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WorkspaceSize {
    pub gaussians: usize,
    pub pixels: usize,
    pub tiles: usize,
    pub intersections: u32,
}

impl WorkspaceSize {
    fn holds(&self, other: &WorkspaceSize) -> bool {
        self.gaussians >= other.gaussians
            && self.pixels >= other.pixels
            && self.tiles >= other.tiles
            && self.intersections >= other.intersections
    }
}

/// Every intermediate of one forward pass and what its backward pass reads.
#[derive(Debug)]
pub struct RenderWorkspace {
    pub size: WorkspaceSize,
    pub uniforms: wgpu::Buffer,
    /// See `tile_budget.wgsl` for the slots.
    pub counts: wgpu::Buffer,
    pub projected: wgpu::Buffer,
    pub tile_counts: wgpu::Buffer,
    pub depth_keys: wgpu::Buffer,
    pub depth_values: wgpu::Buffer,
    pub tile_counts_in_depth_order: wgpu::Buffer,
    pub tile_offsets: wgpu::Buffer,
    pub intersection_tiles: wgpu::Buffer,
    pub intersection_gaussians: wgpu::Buffer,
    pub tile_ranges: wgpu::Buffer,
    pub image: wgpu::Buffer,
    pub final_transmittance: wgpu::Buffer,
    pub last_contributor: wgpu::Buffer,
    pub depth: wgpu::Buffer,
    /// Per image, a u32 per [`crate::OCCUPANCY_CELL`] square (object renders mark it).
    pub occupancy: wgpu::Buffer,
    pub grad_projected: wgpu::Buffer,
    /// An object batch's slots (see `slot_table`), written through the encoder per batch.
    pub slot_table: wgpu::Buffer,
}

/// Slots a workspace's slot table holds; larger batches get a table of their own.
pub const SLOT_TABLE_CAPACITY: usize = 64;

fn storage(
    ctx: &GpuContext,
    label: &str,
    bytes: usize,
    extra: wgpu::BufferUsages,
) -> Result<wgpu::Buffer, GpuError> {
    ctx.storage_buffer_with_usage(label, bytes as u64, extra)
}

impl RenderWorkspace {
    pub fn new(ctx: &GpuContext, size: WorkspaceSize) -> Result<Self, GpuError> {
        let none = wgpu::BufferUsages::empty();
        let gaussians = size.gaussians;
        let pixels = size.pixels;
        let intersections = size.intersections as usize;
        Ok(Self {
            size,
            uniforms: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("render uniforms"),
                size: std::mem::size_of::<super::uniforms::RenderUniforms>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            counts: storage(
                ctx,
                "render counts",
                COUNT_SLOTS * 4,
                wgpu::BufferUsages::INDIRECT,
            )?,
            projected: storage(ctx, "projected splats", gaussians * 48, none)?,
            tile_counts: storage(ctx, "tile counts", gaussians * 4, none)?,
            depth_keys: storage(ctx, "depth keys", gaussians * 4, none)?,
            depth_values: storage(ctx, "depth order", gaussians * 4, none)?,
            tile_counts_in_depth_order: storage(
                ctx,
                "tile counts in depth order",
                gaussians * 4,
                none,
            )?,
            tile_offsets: storage(ctx, "tile offsets", (gaussians + 1) * 4, none)?,
            intersection_tiles: storage(ctx, "intersection tiles", intersections * 4, none)?,
            intersection_gaussians: storage(
                ctx,
                "intersection gaussians",
                intersections * 4,
                none,
            )?,
            tile_ranges: storage(ctx, "tile ranges", size.tiles * 8, none)?,
            image: storage(ctx, "rendered image", pixels * 16, none)?,
            final_transmittance: storage(ctx, "final transmittance", pixels * 4, none)?,
            last_contributor: storage(ctx, "last contributor", pixels * 4, none)?,
            depth: storage(ctx, "rendered depth", pixels * 4, none)?,
            occupancy: storage(
                ctx,
                "occupancy",
                size.tiles * OCCUPANCY_CELLS_PER_TILE * 4,
                none,
            )?,
            slot_table: storage(ctx, "object slots", SLOT_TABLE_CAPACITY * 8, none)?,
            grad_projected: storage(
                ctx,
                "projected splat gradients",
                gaussians * GRAD_STRIDE * 4,
                none,
            )?,
        })
    }
}

/// Workspaces not in use. A render takes one that is large enough (or makes one) and its
/// [`super::RenderOutput`] gives it back when dropped.
#[derive(Debug, Default)]
pub struct WorkspacePool {
    free: std::sync::Mutex<Vec<RenderWorkspace>>,
}

impl WorkspacePool {
    pub fn take(&self, ctx: &GpuContext, size: WorkspaceSize) -> Result<RenderWorkspace, GpuError> {
        let mut free = self
            .free
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(position) = free.iter().position(|w| w.size.holds(&size)) {
            return Ok(free.swap_remove(position));
        }
        drop(free);
        RenderWorkspace::new(ctx, size)
    }

    pub fn give_back(&self, workspace: RenderWorkspace) {
        let mut free = self
            .free
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        free.push(workspace);
    }

    /// Drops pooled workspaces with fewer intersection slots than `intersections`.
    pub fn retire_smaller_than(&self, intersections: u32) {
        let mut free = self
            .free
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        free.retain(|w| w.size.intersections >= intersections);
    }
}
