//! GPU renderer: forward (image) and backward (gradients) passes over a [`GpuGaussians`](crate::GpuGaussians) scene.
//!
//! Kernel decomposition (after gsplat / Brush), one WGSL file per concern:
//!
//! | step | kernel (shader file)                         | work                                         |
//! |------|----------------------------------------------|----------------------------------------------|
//! | 1    | `project_forward.wgsl` (+ `sh.wgsl`)          | per Gaussian: cull, EWA splat, SH colour, tile count, depth key |
//! | 2    | radix sort (`gpu::sort`)                     | Gaussians by depth (f32 bits; culled last)   |
//! | 3    | `tile_count_in_depth_order.wgsl`              | tile counts gathered in depth order          |
//! | 4    | exclusive scan (`gpu::scan`)                 | intersection offsets; the total on the GPU   |
//! | 5    | `tile_budget.wgsl`                            | clamp total to capacity, indirect sizes, peak |
//! | 6    | `tile_emit.wgsl`                              | (tile, Gaussian) pairs in depth order        |
//! | 7    | radix sort (stable)                          | pairs by tile id: depth order within a tile  |
//! | 8    | `tile_ranges.wgsl` (indirect)                 | each tile's [start, end)                     |
//! | 9    | `rasterize_forward.wgsl`                      | 16x16 workgroup per tile, batches of 256     |
//!
//! Software adapters (lavapipe) run `rasterize_forward_columns.wgsl` for step 9 and
//! `rasterize_backward_columns.wgsl` for the backward: the same arithmetic per pixel, with a column
//! of pixels per invocation, and each subgroup walking its tile's splats on its own, a splat per
//! lane at a time, only those whose footprint reaches its block of pixels
//! (`rasterize_lane_chunk.wgsl`), so that each splat read and each set of gradient atomics serves
//! many pixels ([`RasterVariant`]).
//!
//! Backward: `rasterize_backward.wgsl` (per pixel, back to front, float atomics into per-Gaussian
//! screen-space gradients), then `project_backward.wgsl` (geometry) and `sh_backward.wgsl`
//! (colour), which ADD into [`GpuGaussianGrads`](crate::GpuGaussianGrads).
//!
//! Object renders of one camera (the Segment-then-Splat object loss) batch on top of that
//! camera's full render, sharing its projection, depth order and projection backward
//! ([`Renderer::forward_objects`], module `object_batch`).
//!
//! No CPU read-back happens in `forward` or `backward`: counts stay on the GPU and
//! intersection-dependent work is dispatched indirectly. See [`Renderer`] for the capacity policy.

mod capacity;
mod kernels;
mod object_batch;
mod output;
mod renderer;
mod uniforms;
mod workspace;

pub use capacity::CapacityReport;
pub use kernels::RasterVariant;
pub use object_batch::{ObjectBatchError, ObjectBatchOutput, ObjectSlot, slot_table};
pub use output::{RenderError, RenderOutput};
pub(crate) use renderer::RENDER_ATTEMPTS;
pub use renderer::Renderer;
pub use uniforms::RenderUniforms;
pub use workspace::GRAD_STRIDE;
