//! The render pipelines, compiled once per device.

use segsplat_gpu::RasterLayout;
use segsplat_gpu::{GpuContext, GpuError, Kernel};

const COMMON: &str = include_str!("shaders/project_common.wgsl");
const SH: &str = include_str!("shaders/sh.wgsl");
const PROJECT_FORWARD: &str = include_str!("shaders/project_forward.wgsl");
const TILE_COUNT_IN_DEPTH_ORDER: &str = include_str!("shaders/tile_count_in_depth_order.wgsl");
const TILE_BUDGET: &str = include_str!("shaders/tile_budget.wgsl");
const TILE_EMIT: &str = include_str!("shaders/tile_emit.wgsl");
const TILE_FOOTPRINT: &str = include_str!("shaders/tile_footprint.wgsl");
const RENDER_SLOTS: &str = include_str!("shaders/render_slots.wgsl");
const OBJECT_TILE_COUNT: &str = include_str!("shaders/object_tile_count.wgsl");
const TILE_EMIT_SPLAT: &str = include_str!("shaders/tile_emit_splat.wgsl");
const OBJECT_TILE_EMIT: &str = include_str!("shaders/object_tile_emit.wgsl");
const TILE_RANGES: &str = include_str!("shaders/tile_ranges.wgsl");
const RASTERIZE_BATCH: &str = include_str!("shaders/rasterize_batch.wgsl");
const RASTERIZE_LANE_CHUNK: &str = include_str!("shaders/rasterize_lane_chunk.wgsl");
const RASTERIZE_FORWARD_COMMON: &str = include_str!("shaders/rasterize_forward_common.wgsl");
const RASTERIZE_FORWARD: &str = include_str!("shaders/rasterize_forward.wgsl");
const RASTERIZE_FORWARD_COLUMNS: &str = include_str!("shaders/rasterize_forward_columns.wgsl");
const RASTERIZE_BACKWARD_COMMON: &str = include_str!("shaders/rasterize_backward_common.wgsl");
const RASTERIZE_BACKWARD: &str = include_str!("shaders/rasterize_backward.wgsl");
const RASTERIZE_BACKWARD_COLUMNS: &str = include_str!("shaders/rasterize_backward_columns.wgsl");
const GRAD_ATOMICS_NATIVE: &str = include_str!("shaders/rasterize_grad_atomics_native.wgsl");
const GRAD_ATOMICS_CAS: &str = include_str!("shaders/rasterize_grad_atomics_cas.wgsl");
const GRAD_FRAGMENT: &str = include_str!("shaders/rasterize_grad_fragment.wgsl");
const GRAD_EMIT_DIRECT: &str = include_str!("shaders/rasterize_grad_emit_direct.wgsl");
const GRAD_EMIT_SUBGROUP: &str = include_str!("shaders/rasterize_grad_emit_subgroup.wgsl");
const GRAD_EMIT_SHUFFLE: &str = include_str!("shaders/rasterize_grad_emit_shuffle.wgsl");
const PROJECT_BACKWARD: &str = include_str!("shaders/project_backward.wgsl");
const SH_BACKWARD: &str = include_str!("shaders/sh_backward.wgsl");

/// One pipeline per kernel file.
#[derive(Debug)]
pub struct RenderKernels {
    pub project_forward: Kernel,
    pub tile_count_in_depth_order: Kernel,
    pub tile_budget: Kernel,
    pub tile_emit: Kernel,
    pub object_tile_count: Kernel,
    pub object_tile_emit: Kernel,
    pub tile_ranges: Kernel,
    pub rasterize_forward: Kernel,
    pub rasterize_backward: Kernel,
    pub project_backward: Kernel,
    pub sh_backward: Kernel,
}

/// Which rasterize kernels run: all give the same images and gradients.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RasterVariant {
    /// One pixel per invocation, each adding its own gradients (adapters without subgroups).
    Pixels,
    /// One pixel per invocation, each splat's gradients summed over the subgroup by
    /// `subgroupAdd` before the atomics (hardware, where same-address atomics from a warp
    /// serialise; on lavapipe it walks the lanes one by one and costs more than the atomics it
    /// saves: 512 px, 200k random Gaussians, backward 8.6-10.5 s with sums vs 3.6-4.7 s
    /// without).
    PixelsSubgroupSums,
    /// A column of pixels per invocation and each subgroup walking its tile's splats on its own,
    /// a splat per lane at a time (`rasterize_*_columns.wgsl`, `rasterize_lane_chunk.wgsl`):
    /// software adapters with subgroups. A CPU adapter reads memory lane by lane and its float
    /// atomics are compare-and-swap loops, so every splat read and every atomic serves many
    /// pixels.
    Columns,
}

impl RasterVariant {
    /// The kernels that suit the adapter, unless the context forces a layout
    /// ([`segsplat_gpu::KernelChoices`]). Columns need subgroups: without them a request for
    /// columns gets pixels.
    pub fn for_adapter(ctx: &GpuContext) -> Self {
        let columns = match ctx.kernel_choices.raster {
            Some(layout) => layout == RasterLayout::Columns,
            None => ctx.report.is_software,
        };
        match (columns, ctx.has_subgroups()) {
            (true, true) => Self::Columns,
            (true, false) => {
                if ctx.report.is_software {
                    tracing::warn!(
                        "the software adapter has no subgroups: rasterizing a pixel per invocation"
                    );
                }
                Self::Pixels
            }
            (false, true) if !ctx.report.is_software => Self::PixelsSubgroupSums,
            (false, _) => Self::Pixels,
        }
    }

    /// Every variant the adapter can run.
    pub fn supported(ctx: &GpuContext) -> Vec<Self> {
        if ctx.has_subgroups() {
            vec![Self::Pixels, Self::PixelsSubgroupSums, Self::Columns]
        } else {
            vec![Self::Pixels]
        }
    }
}

impl RenderKernels {
    pub fn new(ctx: &GpuContext, variant: RasterVariant) -> Result<Self, GpuError> {
        let build = |label: &'static str, sources: &[&str], entry: &str| {
            Kernel::new(ctx, label, sources, entry, &[])
        };
        // Native f32 atomics where the device has them, a CAS loop where it does not.
        let atomics = if ctx.has_float32_atomics() {
            GRAD_ATOMICS_NATIVE
        } else {
            GRAD_ATOMICS_CAS
        };
        // Pixel kernels stage batches of splats in workgroup memory; column kernels walk them a
        // splat per subgroup lane, culled by footprint.
        let (forward_label, forward_body, backward_label, backward_body, walk, grad_emit) =
            match variant {
                RasterVariant::Pixels => (
                    "rasterize_forward",
                    RASTERIZE_FORWARD,
                    "rasterize_backward",
                    RASTERIZE_BACKWARD,
                    RASTERIZE_BATCH,
                    GRAD_EMIT_DIRECT,
                ),
                RasterVariant::PixelsSubgroupSums => (
                    "rasterize_forward",
                    RASTERIZE_FORWARD,
                    "rasterize_backward",
                    RASTERIZE_BACKWARD,
                    RASTERIZE_BATCH,
                    GRAD_EMIT_SUBGROUP,
                ),
                RasterVariant::Columns => (
                    "rasterize_forward_columns",
                    RASTERIZE_FORWARD_COLUMNS,
                    "rasterize_backward_columns",
                    RASTERIZE_BACKWARD_COLUMNS,
                    RASTERIZE_LANE_CHUNK,
                    GRAD_EMIT_SHUFFLE,
                ),
            };
        if variant != RasterVariant::Pixels && !ctx.has_subgroups() {
            return Err(GpuError::Unsupported(format!(
                "{variant:?} rasterization needs subgroups, which this adapter lacks"
            )));
        }
        Ok(Self {
            project_forward: build(
                "project_forward",
                &[COMMON, SH, TILE_FOOTPRINT, PROJECT_FORWARD],
                "project_forward",
            )?,
            tile_count_in_depth_order: build(
                "tile_count_in_depth_order",
                &[COMMON, TILE_COUNT_IN_DEPTH_ORDER],
                "tile_count_in_depth_order",
            )?,
            tile_budget: build("tile_budget", &[COMMON, TILE_BUDGET], "tile_budget")?,
            tile_emit: build(
                "tile_emit",
                &[COMMON, TILE_FOOTPRINT, TILE_EMIT_SPLAT, TILE_EMIT],
                "tile_emit",
            )?,
            object_tile_count: build(
                "object_tile_count",
                &[COMMON, OBJECT_TILE_COUNT],
                "object_tile_count",
            )?,
            object_tile_emit: build(
                "object_tile_emit",
                &[COMMON, TILE_FOOTPRINT, TILE_EMIT_SPLAT, OBJECT_TILE_EMIT],
                "object_tile_emit",
            )?,
            tile_ranges: build(
                "tile_ranges",
                &[COMMON, TILE_RANGES],
                "tile_ranges_from_sorted",
            )?,
            rasterize_forward: build(
                forward_label,
                &[
                    COMMON,
                    TILE_FOOTPRINT,
                    RASTERIZE_FORWARD_COMMON,
                    RENDER_SLOTS,
                    walk,
                    forward_body,
                ],
                "rasterize_forward",
            )?,
            rasterize_backward: build(
                backward_label,
                &[
                    atomics,
                    COMMON,
                    TILE_FOOTPRINT,
                    RASTERIZE_BACKWARD_COMMON,
                    RENDER_SLOTS,
                    walk,
                    GRAD_FRAGMENT,
                    grad_emit,
                    backward_body,
                ],
                "rasterize_backward",
            )?,
            project_backward: build(
                "project_backward",
                &[COMMON, PROJECT_BACKWARD],
                "project_backward",
            )?,
            sh_backward: build("sh_backward", &[COMMON, SH, SH_BACKWARD], "sh_backward")?,
        })
    }
}
