//! The deformation field's pipelines and the small typed dispatch helpers over them.

use segsplat_gpu::GemmLayout;
use segsplat_gpu::kernel::{workgroups_2d, workgroups_for};
use segsplat_gpu::{GpuContext, GpuError, Kernel};

use super::gemm_broadcast::{BroadcastBlock, SUBGROUP_LANES};

const GEMM_COMMON: &str = include_str!("shaders/mlp_gemm_common.wgsl");
const GEMM: &str = include_str!("shaders/mlp_gemm.wgsl");
const GEMM_ROWS: &str = include_str!("shaders/mlp_gemm_rows.wgsl");
const COLUMN_SUMS: &str = include_str!("shaders/mlp_column_sums.wgsl");
const SPLIT_REDUCE: &str = include_str!("shaders/mlp_split_reduce.wgsl");
const ENCODE: &str = include_str!("shaders/deform_encode.wgsl");
const APPLY_COMMON: &str = include_str!("shaders/deform_apply_common.wgsl");
const APPLY_FORWARD: &str = include_str!("shaders/deform_apply_forward.wgsl");
const APPLY_BACKWARD: &str = include_str!("shaders/deform_apply_backward.wgsl");

/// Output tile side of `mlp_gemm.wgsl`.
const GEMM_TILE: u32 = 64;
/// Depth tile of `mlp_gemm.wgsl`: split ranges are multiples of it.
const GEMM_DEPTH_TILE: u32 = 16;
/// Rows and columns of one `mlp_gemm_rows.wgsl` invocation's outputs.
const GEMM_ROWS_PER_LANE: u32 = 4;
const GEMM_ROWS_COLS: u32 = 8;
/// Invocations of a `mlp_gemm_rows.wgsl` workgroup (its `LANES`), one pipeline each, shortest
/// first: a product takes the first whose workgroup covers its rows (64, 128, 256), else the
/// last. As with the broadcast blocks below, a 64-row weight gradient computed in 256-row
/// workgroups did its work four times over.
const ROWS_LANES: [u32; 3] = [16, 32, 64];
pub const FLAG_BIAS: u32 = 1;
pub const FLAG_RELU: u32 = 2;
pub const FLAG_MASK: u32 = 4;

/// Uniform block of the GEMM kernels (`mlp_gemm_common.wgsl` lists the three products).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GemmParams {
    pub rows: u32,
    pub cols: u32,
    pub depth: u32,
    pub depth_per_split: u32,
    pub a_offset: u32,
    pub a_row_stride: u32,
    pub a_depth_stride: u32,
    pub b_offset: u32,
    pub b_depth_stride: u32,
    pub b_col_stride: u32,
    pub c_offset: u32,
    pub c_row_stride: u32,
    pub c_split_stride: u32,
    pub bias_offset: u32,
    pub mask_offset: u32,
    pub mask_row_stride: u32,
    pub flags: u32,
    pub _pad: [u32; 3],
}

/// Which of a linear layer's three products a GEMM computes (`mlp_gemm_common.wgsl`): the same
/// kernel runs all three, and a kernel profile times each under its own name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GemmProduct {
    Forward,
    InputGradient,
    WeightGradient,
}

impl GemmProduct {
    /// The product's name in `bench-matmul`'s report.
    pub fn name(self) -> &'static str {
        match self {
            Self::Forward => "forward",
            Self::InputGradient => "input_gradient",
            Self::WeightGradient => "weight_gradient",
        }
    }

    /// The name `bench --profile-kernels` and a job's kernel times give this product on
    /// `pipelines`' kernel: the kernel's label, then the product.
    fn profile_name(self, pipelines: &GemmPipelines) -> &'static str {
        const NAMES: [[&str; 3]; 3] = [
            [
                "mlp_gemm forward",
                "mlp_gemm input_gradient",
                "mlp_gemm weight_gradient",
            ],
            [
                "mlp_gemm_rows forward",
                "mlp_gemm_rows input_gradient",
                "mlp_gemm_rows weight_gradient",
            ],
            [
                "mlp_gemm_broadcast forward",
                "mlp_gemm_broadcast input_gradient",
                "mlp_gemm_broadcast weight_gradient",
            ],
        ];
        let kernel = match pipelines {
            GemmPipelines::Tiled(_) => 0,
            GemmPipelines::Rows(_) => 1,
            GemmPipelines::Broadcast(_) => 2,
        };
        NAMES[kernel][self as usize]
    }
}

/// The buffers of one GEMM; `bias` and `mask` are bound even when the flags ignore them.
pub struct GemmBuffers<'a> {
    pub a: &'a wgpu::Buffer,
    pub b: &'a wgpu::Buffer,
    pub bias: &'a wgpu::Buffer,
    pub mask: &'a wgpu::Buffer,
    pub c: &'a wgpu::Buffer,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ColumnSumParams {
    rows: u32,
    cols: u32,
    rows_per_split: u32,
    source_offset: u32,
    source_row_stride: u32,
    _pad: [u32; 3],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ReduceParams {
    count: u32,
    splits: u32,
    target_offset: u32,
    _pad: u32,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct EncodeParams {
    pub count: u32,
    pub first: u32,
    pub row_stride: u32,
    pub position_frequencies: u32,
    pub time_frequencies: u32,
    pub time: f32,
    pub _pad: [u32; 2],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ApplyParams {
    pub count: u32,
    pub first: u32,
    pub head_stride: u32,
    pub screw: u32,
}

/// How the rows summed by a weight or bias gradient are split: enough splits to fill a GPU when
/// the output is small, each a whole number of depth tiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowSplit {
    pub splits: u32,
    pub rows_per_split: u32,
}

pub const MAX_SPLITS: u32 = 32;

/// Rows a split aims at with the tiled kernel (hardware GPUs). A weight gradient's output is a
/// layer's weights, only (outputs / 64) x (inputs / 64) tiles (16-24 for a 256-wide layer), so
/// its workgroups are that times the splits, each looping over its split's rows: at 1024 rows a
/// split, a field over 4,000 Gaussians gave a GPU of 132 compute units 64-96 workgroups of 64
/// depth tiles each; at 256, 256-384 of 16.
const TILED_SPLIT_ROWS: u32 = 256;
/// Rows a split aims at with the software kernels: a CPU adapter runs on a few cores, where more
/// splits only add partial sums to reduce.
const SOFTWARE_SPLIT_ROWS: u32 = 1024;

impl RowSplit {
    /// Splits of about `target` rows (a whole number of depth tiles each), at most
    /// [`MAX_SPLITS`]. Rounding to depth tiles can give a few more rows one split fewer than
    /// fewer rows get, so partial sums are sized for [`MAX_SPLITS`], not for a row count.
    pub fn for_rows(rows: u32, target: u32) -> Self {
        let wanted = rows.div_ceil(target.max(1)).clamp(1, MAX_SPLITS);
        let rows_per_split =
            rows.div_ceil(wanted).div_ceil(GEMM_DEPTH_TILE).max(1) * GEMM_DEPTH_TILE;
        Self {
            splits: rows.div_ceil(rows_per_split).max(1),
            rows_per_split,
        }
    }
}

/// Blocks of the broadcast kernel, shortest workgroup first: a product takes the first whose
/// workgroup covers its rows, else the last. Products of many rows (the Gaussians) take the last,
/// 8 rows an invocation. Weight gradients, whose rows are a layer's outputs (64 in the field a
/// software adapter trains, 256 in the released one, and a head of up to 10), take 4 rows an
/// invocation and only as many subgroups as their rows need: rows past the end are computed and
/// not stored, so the 256-row workgroup alone computed a 64-row product four times over.
const BROADCAST_BLOCKS: [BroadcastBlock; 4] = [
    BroadcastBlock {
        lane_rows: 4,
        col_groups: 4,
        subgroups: 2,
    },
    BroadcastBlock {
        lane_rows: 4,
        col_groups: 4,
        subgroups: 4,
    },
    BroadcastBlock {
        lane_rows: 4,
        col_groups: 4,
        subgroups: 8,
    },
    BroadcastBlock {
        lane_rows: 8,
        col_groups: 4,
        subgroups: 8,
    },
];

/// Which GEMM kernel the field runs: all compute the same products.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GemmKernel {
    /// `mlp_gemm.wgsl`: 64x64 output tiles staged through workgroup memory (hardware GPUs).
    Tiled,
    /// `mlp_gemm_rows.wgsl`: a 4 x 8 output block per invocation, no workgroup memory or
    /// barriers (software adapters without 8-lane subgroups).
    Rows,
    /// `gemm_broadcast.rs`: rows per invocation, the weights' side shared by subgroup
    /// broadcasts (software adapters whose subgroups are exactly 8 lanes: lavapipe on AVX2).
    Broadcast,
}

impl GemmKernel {
    /// The name `SEGSPLAT_GEMM_KERNEL` and `workers.adapters.kernels.gemm` give it
    /// ([`GemmLayout::name`]).
    pub fn name(self) -> &'static str {
        let layout = match self {
            Self::Tiled => GemmLayout::Tiled,
            Self::Rows => GemmLayout::Rows,
            Self::Broadcast => GemmLayout::Broadcast,
        };
        layout.name()
    }

    /// The kernel that suits the adapter, unless the context forces one
    /// ([`segsplat_gpu::KernelChoices`]).
    pub fn for_adapter(ctx: &GpuContext) -> Self {
        match ctx.kernel_choices.gemm {
            Some(GemmLayout::Tiled) => Self::Tiled,
            Some(GemmLayout::Rows) => Self::Rows,
            Some(GemmLayout::Broadcast) => Self::Broadcast,
            None if ctx.report.is_software && Self::Broadcast.runs_on(ctx) => Self::Broadcast,
            None if ctx.report.is_software => Self::Rows,
            None => Self::Tiled,
        }
    }

    /// Whether the adapter can run this kernel: the broadcast kernel names 8 lanes of a
    /// subgroup, so it needs subgroups of exactly that size.
    pub fn runs_on(self, ctx: &GpuContext) -> bool {
        match self {
            Self::Tiled | Self::Rows => true,
            Self::Broadcast => {
                ctx.has_subgroups() && ctx.report.subgroup_sizes == [SUBGROUP_LANES; 2]
            }
        }
    }

    /// Every kernel the adapter can run (the tests check each).
    pub fn supported(ctx: &GpuContext) -> Vec<Self> {
        [Self::Tiled, Self::Rows, Self::Broadcast]
            .into_iter()
            .filter(|kernel| kernel.runs_on(ctx))
            .collect()
    }
}

/// The compiled GEMM pipelines of one [`GemmKernel`].
#[derive(Debug)]
enum GemmPipelines {
    Tiled(Kernel),
    /// One pipeline per entry of `ROWS_LANES`, in its order.
    Rows(Vec<Kernel>),
    /// One pipeline per block of `BROADCAST_BLOCKS`, in its order.
    Broadcast(Vec<Kernel>),
}

/// The first of `heights` (workgroup rows, shortest first) that covers `rows`, else the last:
/// rows past a product's end are computed and not stored, so a taller workgroup only wastes work.
fn shortest_covering(heights: &[u32], rows: u32) -> usize {
    heights
        .iter()
        .position(|&height| rows <= height)
        .unwrap_or(heights.len().saturating_sub(1))
}

impl GemmPipelines {
    /// The pipeline for a product of `rows` rows and the output block one workgroup covers
    /// (columns, rows).
    fn for_rows(&self, rows: u32) -> (&Kernel, u32, u32) {
        match self {
            Self::Tiled(kernel) => (kernel, GEMM_TILE, GEMM_TILE),
            Self::Rows(kernels) => {
                let heights = ROWS_LANES.map(|lanes| lanes * GEMM_ROWS_PER_LANE);
                let index = shortest_covering(&heights, rows);
                (&kernels[index], GEMM_ROWS_COLS, heights[index])
            }
            Self::Broadcast(kernels) => {
                let index =
                    shortest_covering(&BROADCAST_BLOCKS.map(|block| block.workgroup_rows()), rows);
                let (kernel, block) = (&kernels[index], BROADCAST_BLOCKS[index]);
                (kernel, block.workgroup_cols(), block.workgroup_rows())
            }
        }
    }
}

#[derive(Debug)]
pub struct DeformKernels {
    gemm: GemmPipelines,
    column_sums: Kernel,
    split_reduce: Kernel,
    encode: Kernel,
    apply_forward: Kernel,
    apply_backward: Kernel,
}

fn per_item_grid(ctx: &GpuContext, items: u32) -> [u32; 3] {
    workgroups_2d(
        workgroups_for(items, 256),
        ctx.limits.max_compute_workgroups_per_dimension,
    )
}

impl DeformKernels {
    pub fn with_gemm(ctx: &GpuContext, gemm_kind: GemmKernel) -> Result<Self, GpuError> {
        let build = |label: &'static str, sources: &[&str], entry: &str| {
            Kernel::new(ctx, label, sources, entry, &[])
        };
        if !gemm_kind.runs_on(ctx) {
            return Err(GpuError::Device(format!(
                "the {gemm_kind:?} GEMM kernel needs subgroups of {SUBGROUP_LANES} lanes; this adapter has {:?}",
                ctx.report.subgroup_sizes
            )));
        }
        let gemm = match gemm_kind {
            GemmKernel::Tiled => {
                GemmPipelines::Tiled(build("mlp_gemm", &[GEMM_COMMON, GEMM], "gemm")?)
            }
            GemmKernel::Rows => GemmPipelines::Rows(
                ROWS_LANES
                    .iter()
                    .map(|&lanes| {
                        Kernel::new(
                            ctx,
                            "mlp_gemm_rows",
                            &[GEMM_COMMON, GEMM_ROWS],
                            "gemm_rows",
                            &[("LANES", f64::from(lanes))],
                        )
                    })
                    .collect::<Result<_, _>>()?,
            ),
            GemmKernel::Broadcast => GemmPipelines::Broadcast(
                BROADCAST_BLOCKS
                    .iter()
                    .map(|block| {
                        build(
                            "mlp_gemm_broadcast",
                            &[GEMM_COMMON, &block.source()],
                            "gemm_broadcast",
                        )
                    })
                    .collect::<Result<_, _>>()?,
            ),
        };
        Ok(Self {
            gemm,
            column_sums: build("mlp_column_sums", &[COLUMN_SUMS], "column_sums")?,
            split_reduce: build("mlp_split_reduce", &[SPLIT_REDUCE], "split_reduce")?,
            encode: build("deform_encode", &[ENCODE], "deform_encode")?,
            apply_forward: build(
                "deform_apply_forward",
                &[APPLY_COMMON, APPLY_FORWARD],
                "deform_apply_forward",
            )?,
            apply_backward: build(
                "deform_apply_backward",
                &[APPLY_COMMON, APPLY_BACKWARD],
                "deform_apply_backward",
            )?,
        })
    }

    /// How a weight or bias gradient over `rows` rows is split with this kernel.
    pub fn row_split(&self, rows: u32) -> RowSplit {
        let target = match self.gemm {
            GemmPipelines::Tiled(_) => TILED_SPLIT_ROWS,
            GemmPipelines::Rows(_) | GemmPipelines::Broadcast(_) => SOFTWARE_SPLIT_ROWS,
        };
        RowSplit::for_rows(rows, target)
    }

    /// Records `c = epilogue(a b)` over `splits` depth ranges (`params.c_split_stride` apart);
    /// `product` names it in kernel profiles.
    pub fn gemm(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        product: GemmProduct,
        params: GemmParams,
        splits: u32,
        buffers: GemmBuffers<'_>,
    ) {
        let (kernel, col_block, row_block) = self.gemm.for_rows(params.rows);
        let bind = kernel.bind_params(
            ctx,
            bytemuck::bytes_of(&params),
            &[buffers.a, buffers.b, buffers.bias, buffers.mask, buffers.c],
        );
        let grid = [
            params.cols.div_ceil(col_block).max(1),
            params.rows.div_ceil(row_block).max(1),
            splits.max(1),
        ];
        kernel.dispatch_named(encoder, &bind, grid, product.profile_name(&self.gemm));
    }

    /// Records per-split column sums of `source` rows (`[rows, cols]`, row stride given) into
    /// `partials[split * cols + col]`.
    #[allow(clippy::too_many_arguments)]
    pub fn column_sums(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        source: &wgpu::Buffer,
        source_offset: u32,
        source_row_stride: u32,
        rows: u32,
        cols: u32,
        split: RowSplit,
        partials: &wgpu::Buffer,
    ) {
        let params = ColumnSumParams {
            rows,
            cols,
            rows_per_split: split.rows_per_split,
            source_offset,
            source_row_stride,
            _pad: [0; 3],
        };
        let bind =
            self.column_sums
                .bind_params(ctx, bytemuck::bytes_of(&params), &[source, partials]);
        self.column_sums
            .dispatch(encoder, &bind, [cols.div_ceil(64).max(1), split.splits, 1]);
    }

    /// Records `target[offset + i] += sum_s partials[s * count + i]`.
    #[allow(clippy::too_many_arguments)]
    pub fn split_reduce(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        partials: &wgpu::Buffer,
        count: u32,
        splits: u32,
        target: &wgpu::Buffer,
        target_offset: u32,
    ) {
        let params = ReduceParams {
            count,
            splits,
            target_offset,
            _pad: 0,
        };
        let bind =
            self.split_reduce
                .bind_params(ctx, bytemuck::bytes_of(&params), &[partials, target]);
        self.split_reduce
            .dispatch(encoder, &bind, per_item_grid(ctx, count));
    }

    pub fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        params: EncodeParams,
        means: &wgpu::Buffer,
        encoded: &wgpu::Buffer,
    ) {
        let bind = self
            .encode
            .bind_params(ctx, bytemuck::bytes_of(&params), &[means, encoded]);
        self.encode
            .dispatch(encoder, &bind, per_item_grid(ctx, params.count));
    }

    /// Binding order: head, canonical means, rotations, log-scales, then the three deformed
    /// outputs.
    pub fn apply_forward(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        params: ApplyParams,
        buffers: &[&wgpu::Buffer; 7],
    ) {
        dispatch_apply(&self.apply_forward, ctx, encoder, params, buffers);
    }

    /// Binding order: head, canonical means, rotations, grad means, grad rotations, grad
    /// log-scales, grad head.
    pub fn apply_backward(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        params: ApplyParams,
        buffers: &[&wgpu::Buffer; 7],
    ) {
        dispatch_apply(&self.apply_backward, ctx, encoder, params, buffers);
    }
}

/// One `deform_apply_*` dispatch: the uniforms, then `buffers` in binding order.
fn dispatch_apply(
    kernel: &Kernel,
    ctx: &GpuContext,
    encoder: &mut segsplat_gpu::Encoder,
    params: ApplyParams,
    buffers: &[&wgpu::Buffer; 7],
) {
    let bind = kernel.bind_params(ctx, bytemuck::bytes_of(&params), buffers);
    kernel.dispatch(encoder, &bind, per_item_grid(ctx, params.count));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_splits_cover_the_rows_in_depth_tiles() {
        for target in [TILED_SPLIT_ROWS, SOFTWARE_SPLIT_ROWS] {
            for rows in 1..40_000u32 {
                let split = RowSplit::for_rows(rows, target);
                assert!(
                    (1..=MAX_SPLITS).contains(&split.splits),
                    "{rows}: {split:?}"
                );
                assert_eq!(
                    split.rows_per_split % GEMM_DEPTH_TILE,
                    0,
                    "{rows}: {split:?}"
                );
                assert!(
                    split.splits * split.rows_per_split >= rows,
                    "{rows}: {split:?}"
                );
                assert!(
                    (split.splits - 1) * split.rows_per_split < rows,
                    "{rows}: an empty split {split:?}"
                );
            }
        }
        // A field over 4,000 Gaussians: 16 splits on a GPU, 4 on a CPU adapter.
        assert_eq!(RowSplit::for_rows(4000, TILED_SPLIT_ROWS).splits, 16);
        assert_eq!(RowSplit::for_rows(4000, SOFTWARE_SPLIT_ROWS).splits, 4);
    }
}
