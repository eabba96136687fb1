//! The render pipelines, compiled once per device.

use crate::gpu::validation::validated;
use crate::gpu::{GpuContext, GpuError, Kernel};

const COMMON: &str = include_str!("../../../shaders/project_common.wgsl");
const SH: &str = include_str!("../../../shaders/sh.wgsl");
const PROJECT_FORWARD: &str = include_str!("../../../shaders/project_forward.wgsl");
const TILE_COUNT_IN_DEPTH_ORDER: &str =
    include_str!("../../../shaders/tile_count_in_depth_order.wgsl");
const TILE_BUDGET: &str = include_str!("../../../shaders/tile_budget.wgsl");
const TILE_EMIT: &str = include_str!("../../../shaders/tile_emit.wgsl");
const TILE_RANGES: &str = include_str!("../../../shaders/tile_ranges.wgsl");
const RASTERIZE_FORWARD_COMMON: &str =
    include_str!("../../../shaders/rasterize_forward_common.wgsl");
const RASTERIZE_FORWARD: &str = include_str!("../../../shaders/rasterize_forward.wgsl");
const RASTERIZE_FORWARD_COLUMNS: &str =
    include_str!("../../../shaders/rasterize_forward_columns.wgsl");
const RASTERIZE_BACKWARD_COMMON: &str =
    include_str!("../../../shaders/rasterize_backward_common.wgsl");
const RASTERIZE_BACKWARD: &str = include_str!("../../../shaders/rasterize_backward.wgsl");
const RASTERIZE_BACKWARD_COLUMNS: &str =
    include_str!("../../../shaders/rasterize_backward_columns.wgsl");
const GRAD_ATOMICS_NATIVE: &str =
    include_str!("../../../shaders/rasterize_grad_atomics_native.wgsl");
const GRAD_ATOMICS_CAS: &str = include_str!("../../../shaders/rasterize_grad_atomics_cas.wgsl");
const GRAD_FRAGMENT: &str = include_str!("../../../shaders/rasterize_grad_fragment.wgsl");
const GRAD_EMIT_DIRECT: &str = include_str!("../../../shaders/rasterize_grad_emit_direct.wgsl");
const GRAD_EMIT_SUBGROUP: &str = include_str!("../../../shaders/rasterize_grad_emit_subgroup.wgsl");
const PROJECT_BACKWARD: &str = include_str!("../../../shaders/project_backward.wgsl");
const SH_BACKWARD: &str = include_str!("../../../shaders/sh_backward.wgsl");

/// One pipeline per kernel file.
#[derive(Debug)]
pub struct RenderKernels {
    pub project_forward: Kernel,
    pub tile_count_in_depth_order: Kernel,
    pub tile_budget: Kernel,
    pub tile_emit: Kernel,
    pub tile_ranges: Kernel,
    pub rasterize_forward: Kernel,
    pub rasterize_backward: Kernel,
    pub project_backward: Kernel,
    pub sh_backward: Kernel,
}

/// Environment variable that overrides the adapter's rasterize kernels (`pixels` or `columns`),
/// for comparing the two on one machine (docs/benchmarks.md).
pub const RASTER_KERNEL_ENV: &str = "SEGSPLAT_RASTER_KERNEL";

/// Which rasterize kernels run: both give the same images and gradients.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RasterVariant {
    /// A column of pixels per invocation (`rasterize_*_columns.wgsl`, software adapters: a
    /// CPU reads workgroup memory lane by lane and its float atomics are compare-and-swap loops,
    /// so each splat read and each atomic serves several pixels) instead of one pixel per
    /// invocation (GPUs).
    pub columns: bool,
    /// Per-pixel backward only: each fragment's gradients are summed over the subgroup before
    /// the atomics (hardware with subgroups, where same-address atomics from a warp serialise;
    /// on lavapipe's 8-lane subgroups the sums cost more than the atomics they save: 512 px,
    /// 200k random Gaussians, backward 8.6-10.5 s with sums vs 3.6-4.7 s without).
    pub subgroup_sums: bool,
}

impl RasterVariant {
    /// The kernels that suit the adapter, unless [`RASTER_KERNEL_ENV`] names a layout.
    pub fn for_adapter(ctx: &GpuContext) -> Self {
        let mut columns = ctx.report.is_software;
        if let Some(value) = std::env::var_os(RASTER_KERNEL_ENV) {
            match value.to_str() {
                Some("pixels") => columns = false,
                Some("columns") => columns = true,
                _ => tracing::warn!(
                    ?value,
                    "{RASTER_KERNEL_ENV} is neither \"pixels\" nor \"columns\": ignored"
                ),
            }
        }
        Self {
            columns,
            subgroup_sums: !columns && ctx.has_subgroups() && !ctx.report.is_software,
        }
    }
}

impl RenderKernels {
    pub fn new(ctx: &GpuContext, variant: RasterVariant) -> Result<Self, GpuError> {
        let build = |label: &'static str, sources: &[&str], entry: &str| {
            validated(ctx, label, || Kernel::new(ctx, label, sources, entry, &[]))
        };
        // Native f32 atomics where the device has them, a CAS loop where it does not.
        let atomics = if ctx.has_float32_atomics() {
            GRAD_ATOMICS_NATIVE
        } else {
            GRAD_ATOMICS_CAS
        };
        let grad_emit = if variant.subgroup_sums && ctx.has_subgroups() {
            GRAD_EMIT_SUBGROUP
        } else {
            GRAD_EMIT_DIRECT
        };
        Ok(Self {
            project_forward: build(
                "project_forward",
                &[COMMON, SH, PROJECT_FORWARD],
                "project_forward",
            )?,
            tile_count_in_depth_order: build(
                "tile_count_in_depth_order",
                &[COMMON, TILE_COUNT_IN_DEPTH_ORDER],
                "tile_count_in_depth_order",
            )?,
            tile_budget: build("tile_budget", &[COMMON, TILE_BUDGET], "tile_budget")?,
            tile_emit: build("tile_emit", &[COMMON, TILE_EMIT], "tile_emit")?,
            tile_ranges: build(
                "tile_ranges",
                &[COMMON, TILE_RANGES],
                "tile_ranges_from_sorted",
            )?,
            rasterize_forward: if variant.columns {
                build(
                    "rasterize_forward_columns",
                    &[COMMON, RASTERIZE_FORWARD_COMMON, RASTERIZE_FORWARD_COLUMNS],
                    "rasterize_forward",
                )?
            } else {
                build(
                    "rasterize_forward",
                    &[COMMON, RASTERIZE_FORWARD_COMMON, RASTERIZE_FORWARD],
                    "rasterize_forward",
                )?
            },
            rasterize_backward: if variant.columns {
                build(
                    "rasterize_backward_columns",
                    &[
                        atomics,
                        COMMON,
                        RASTERIZE_BACKWARD_COMMON,
                        GRAD_FRAGMENT,
                        RASTERIZE_BACKWARD_COLUMNS,
                    ],
                    "rasterize_backward",
                )?
            } else {
                build(
                    "rasterize_backward",
                    &[
                        atomics,
                        COMMON,
                        RASTERIZE_BACKWARD_COMMON,
                        GRAD_FRAGMENT,
                        grad_emit,
                        RASTERIZE_BACKWARD,
                    ],
                    "rasterize_backward",
                )?
            },
            project_backward: build(
                "project_backward",
                &[COMMON, PROJECT_BACKWARD],
                "project_backward",
            )?,
            sh_backward: build("sh_backward", &[COMMON, SH, SH_BACKWARD], "sh_backward")?,
        })
    }
}
