//! Stable key-value radix sort of u32 pairs on the GPU, with the element count read on the GPU.
//!
//! LSD, 4 bits a pass, only as many passes as `key_bits` needs. Each pass: a per-block digit
//! histogram, an exclusive scan of all histograms (bin-major, so the scan gives every block's
//! destination for every digit; reuses [`ExclusiveScan`]'s level kernels), and a scatter that
//! ranks elements inside their block in input order, which makes the sort stable (the rasterizer
//! relies on it: depth order first, then stably by tile).
//!
//! The count comes from a buffer an earlier kernel wrote (e.g. a scan total): a one-thread plan
//! kernel turns it into every element/block count and indirect dispatch size, so recording a sort
//! never needs a CPU read-back. Scratch buffers are sized for `capacity` and reused.
//!
//! Sorts whose capacity is at most the small-sort limit ([`DEFAULT_SMALL_SORT_LIMIT`]) run in one
//! dispatch instead (`radix_sort_small.wgsl`: one workgroup, every pass): a small scene's 32-bit
//! depth sort is otherwise 25 dispatches, and each costs more than sorting a few thousand keys.

use std::collections::HashMap;

use wgpu::util::DeviceExt;

use crate::kernel::wgsl_u32_constants;
use crate::scan::{
    LEVEL_COUNTS_LEN, MAX_SCAN_LEVELS, ScanDispatch, ScanLevels, ScanScratch, WorkgroupSum,
    block_constant, level_output_counts_without_total,
};
use crate::{Binding, ExclusiveScan, GpuContext, GpuError, Kernel};

/// Elements per sort block and key bits per pass, prepended to the sort kernels
/// (`radix_sort_common.wgsl`) as `SORT_BLOCK` and `RADIX_BITS`.
const SORT_BLOCK_ELEMENTS: u32 = 1024;
const RADIX_BITS: u32 = 4;
const RADIX_BINS: u32 = 1 << RADIX_BITS;

/// Byte offsets of the indirect dispatch sizes the plan kernel writes (`radix_sort_plan.wgsl`).
const DISPATCH_PER_BLOCK_OFFSET: u64 = 0;
const DISPATCH_COPY_OFFSET: u64 = 12;
const DISPATCH_FIRST_SCAN_LEVEL_OFFSET: u64 = 24;
const DISPATCH_ARGS_LEN: usize = 3 * (2 + MAX_SCAN_LEVELS);

const SORT_COMMON: &str = include_str!("shaders/radix_sort_common.wgsl");
const SORT_PLAN: &str = include_str!("shaders/radix_sort_plan.wgsl");
const SORT_HISTOGRAM: &str = include_str!("shaders/radix_sort_histogram.wgsl");
const SORT_SCATTER: &str = include_str!("shaders/radix_sort_scatter.wgsl");
const SORT_COPY: &str = include_str!("shaders/radix_sort_copy.wgsl");
const SORT_SMALL: &str = include_str!("shaders/radix_sort_small.wgsl");

/// Capacities up to this sort in one workgroup and one dispatch (see the module doc). At 16k
/// elements one workgroup's thread walks 256 keys a pass.
pub const DEFAULT_SMALL_SORT_LIMIT: u32 = 16_384;

/// Buffers one sort needs besides the caller's, sized for `capacity` elements.
#[derive(Debug)]
struct SortScratch {
    capacity: u32,
    keys: wgpu::Buffer,
    values: wgpu::Buffer,
    histograms: wgpu::Buffer,
    bin_offsets: wgpu::Buffer,
    scan: ScanScratch,
    scan_levels: usize,
    /// Element count, block count and histogram-scan level counts, written by the plan kernel.
    sort_info: wgpu::Buffer,
    dispatch_args: wgpu::Buffer,
}

/// Stable key-value radix sort (see the module doc).
#[derive(Debug)]
pub struct RadixSort {
    scan: ExclusiveScan,
    plan: Kernel,
    histogram: Kernel,
    scatter: Kernel,
    copy: Kernel,
    small: Kernel,
    /// Capacities up to this take the one-workgroup sort; 0 never does.
    small_limit: u32,
    scratch: Option<SortScratch>,
    /// Uniforms (shift, digit mask) of each pass, by `key_bits`.
    pass_params: HashMap<u32, Vec<wgpu::Buffer>>,
}

impl RadixSort {
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        Self::with_sum(ctx, WorkgroupSum::for_adapter(ctx))
    }

    /// A sort whose scatter and histogram scan add up thread totals the given way.
    pub fn with_sum(ctx: &GpuContext, sum: WorkgroupSum) -> Result<Self, GpuError> {
        let scan = ExclusiveScan::with_sum(ctx, sum)?;
        let kernel = |label, sources: &[&str], entry| Kernel::new(ctx, label, sources, entry, &[]);
        let common = format!(
            "{}{SORT_COMMON}",
            wgsl_u32_constants(&[
                ("RADIX_BITS", RADIX_BITS),
                ("SORT_BLOCK", SORT_BLOCK_ELEMENTS),
            ])
        );
        let common = common.as_str();
        Ok(Self {
            scan,
            plan: kernel(
                "radix_sort_plan",
                &[&block_constant(), common, SORT_PLAN],
                "plan_sort",
            )?,
            histogram: kernel(
                "radix_sort_histogram",
                &[common, SORT_HISTOGRAM],
                "radix_histogram",
            )?,
            scatter: kernel(
                "radix_sort_scatter",
                &[common, sum.source(), SORT_SCATTER],
                "radix_scatter",
            )?,
            copy: kernel("radix_sort_copy", &[common, SORT_COPY], "copy_sorted")?,
            small: kernel("radix_sort_small", &[SORT_SMALL], "small_sort")?,
            small_limit: DEFAULT_SMALL_SORT_LIMIT,
            scratch: None,
            pass_params: HashMap::new(),
        })
    }

    /// The same sort with another small-sort limit (0: always the multi-block passes; tests use
    /// it to run both paths on the same cases).
    pub fn with_small_sort_limit(mut self, limit: u32) -> Self {
        self.small_limit = limit;
        self
    }

    /// Allocates scratch for sorts of up to `capacity` elements, failing when a buffer would not
    /// fit the adapter's storage binding limit. [`RadixSort::encode`] calls it too; call it
    /// up front to turn a too-large capacity into an error before recording work.
    pub fn reserve(&mut self, ctx: &GpuContext, capacity: u32) -> Result<(), GpuError> {
        if self
            .scratch
            .as_ref()
            .is_some_and(|scratch| scratch.capacity >= capacity)
        {
            return Ok(());
        }
        let capacity = capacity.max(1).next_multiple_of(SORT_BLOCK_ELEMENTS);
        let element_bytes = u64::from(capacity) * 4;
        ctx.check_binding_size("radix sort scratch keys", element_bytes)?;
        let histogram_count = capacity / SORT_BLOCK_ELEMENTS * RADIX_BINS;
        let histogram_bytes = (u64::from(histogram_count) + 1) * 4;
        ctx.check_binding_size("radix sort histograms", histogram_bytes)?;
        let storage = |label, bytes, extra_usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage: wgpu::BufferUsages::STORAGE | extra_usage,
                mapped_at_creation: false,
            })
        };
        let none = wgpu::BufferUsages::empty();
        let scan_output_counts = level_output_counts_without_total(histogram_count);
        let mut scan = ScanScratch::default();
        scan.reserve(ctx, &scan_output_counts);
        self.scratch = Some(SortScratch {
            capacity,
            keys: storage("radix sort keys", element_bytes, none),
            values: storage("radix sort values", element_bytes, none),
            histograms: storage("radix sort histograms", histogram_bytes, none),
            bin_offsets: storage("radix sort bin offsets", histogram_bytes, none),
            scan,
            scan_levels: scan_output_counts.len(),
            sort_info: storage("radix sort info", 4 * LEVEL_COUNTS_LEN as u64, none),
            dispatch_args: storage(
                "radix sort dispatch args",
                4 * DISPATCH_ARGS_LEN as u64,
                wgpu::BufferUsages::INDIRECT,
            ),
        });
        Ok(())
    }

    /// Stable ascending sort of (key, value) u32 pairs by the low `key_bits` bits of each key
    /// (higher bits ignored). The element count is read ON THE GPU from `count_buffer` at byte
    /// `count_offset` (a u32 written by an earlier kernel, e.g. the scan total) and is at most
    /// `capacity` (larger counts are clamped); no CPU read-back. Sorted pairs end in
    /// `keys`/`values` (in place); elements from the count on are left untouched.
    ///
    /// When scratch for `capacity` cannot be allocated (see [`RadixSort::reserve`]) nothing is
    /// recorded and an error is logged.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut crate::Encoder,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count_buffer: &wgpu::Buffer,
        count_offset: u64,
        capacity: u32,
        key_bits: u32,
    ) {
        let key_bits = key_bits.min(32);
        let passes = key_bits.div_ceil(RADIX_BITS);
        if passes == 0 {
            return;
        }
        debug_assert!(count_offset.is_multiple_of(4) && count_offset + 4 <= count_buffer.size());
        if let Err(error) = self.reserve(ctx, capacity) {
            tracing::error!(%error, capacity, "radix sort not recorded");
            return;
        }
        self.pass_params
            .entry(key_bits)
            .or_insert_with(|| pass_param_buffers(ctx, key_bits));
        let (Some(scratch), Some(pass_params)) =
            (self.scratch.as_ref(), self.pass_params.get(&key_bits))
        else {
            return;
        };
        if capacity <= self.small_limit {
            let target = SmallSortTarget {
                keys,
                values,
                count_buffer,
                count_offset,
                capacity,
                key_bits,
            };
            self.record_small(ctx, encoder, scratch, &target);
            return;
        }

        self.record_plan(ctx, encoder, scratch, count_buffer, count_offset, capacity);
        let histogram_scan = ScanLevels {
            level_counts: &scratch.sort_info,
            scratch: &scratch.scan,
            dispatch: ScanDispatch::Indirect {
                args: &scratch.dispatch_args,
                first_offset_bytes: DISPATCH_FIRST_SCAN_LEVEL_OFFSET,
                levels: scratch.scan_levels,
            },
        };
        for (pass, params) in pass_params.iter().enumerate() {
            let (keys_in, values_in, keys_out, values_out) = if pass % 2 == 0 {
                (keys, values, &scratch.keys, &scratch.values)
            } else {
                (&scratch.keys, &scratch.values, keys, values)
            };
            let histogram_bind = self.histogram.bind(
                ctx,
                &[&scratch.sort_info, params, keys_in, &scratch.histograms],
            );
            self.histogram.dispatch_indirect(
                encoder,
                &histogram_bind,
                &scratch.dispatch_args,
                DISPATCH_PER_BLOCK_OFFSET,
            );
            self.scan.encode_levels(
                ctx,
                encoder,
                &scratch.histograms,
                &scratch.bin_offsets,
                &histogram_scan,
            );
            let scatter_bind = self.scatter.bind(
                ctx,
                &[
                    &scratch.sort_info,
                    params,
                    keys_in,
                    values_in,
                    &scratch.bin_offsets,
                    keys_out,
                    values_out,
                ],
            );
            self.scatter.dispatch_indirect(
                encoder,
                &scatter_bind,
                &scratch.dispatch_args,
                DISPATCH_PER_BLOCK_OFFSET,
            );
        }
        if passes % 2 == 1 {
            let copy_bind = self.copy.bind(
                ctx,
                &[
                    &scratch.sort_info,
                    &scratch.keys,
                    &scratch.values,
                    keys,
                    values,
                ],
            );
            self.copy.dispatch_indirect(
                encoder,
                &copy_bind,
                &scratch.dispatch_args,
                DISPATCH_COPY_OFFSET,
            );
        }
    }

    /// Records the plan kernel, binding just the aligned window of `count_buffer` that holds the
    /// count (the whole buffer may exceed a storage binding).
    fn record_plan(
        &self,
        ctx: &GpuContext,
        encoder: &mut crate::Encoder,
        scratch: &SortScratch,
        count_buffer: &wgpu::Buffer,
        count_offset: u64,
        capacity: u32,
    ) {
        let window = CountWindow::new(ctx, count_buffer, count_offset);
        let plan_params = [window.index, capacity, scratch.scan_levels as u32, 0];
        let bound = self.plan.bind_entries(
            ctx,
            &[
                window.binding(),
                Binding::Params(bytemuck::cast_slice(&plan_params)),
                Binding::Whole(&scratch.sort_info),
                Binding::Whole(&scratch.dispatch_args),
            ],
        );
        self.plan.dispatch(encoder, &bound, [1, 1, 1]);
    }

    /// Records the one-workgroup sort of every pass (`radix_sort_small.wgsl`).
    fn record_small(
        &self,
        ctx: &GpuContext,
        encoder: &mut crate::Encoder,
        scratch: &SortScratch,
        target: &SmallSortTarget<'_>,
    ) {
        let window = CountWindow::new(ctx, target.count_buffer, target.count_offset);
        let params = [window.index, target.capacity, target.key_bits, 0];
        let bound = self.small.bind_entries(
            ctx,
            &[
                window.binding(),
                Binding::Params(bytemuck::cast_slice(&params)),
                Binding::Whole(target.keys),
                Binding::Whole(target.values),
                Binding::Whole(&scratch.keys),
                Binding::Whole(&scratch.values),
            ],
        );
        self.small.dispatch(encoder, &bound, [1, 1, 1]);
    }
}

/// What a one-workgroup sort sorts (the arguments of [`RadixSort::encode`]).
struct SmallSortTarget<'a> {
    keys: &'a wgpu::Buffer,
    values: &'a wgpu::Buffer,
    count_buffer: &'a wgpu::Buffer,
    count_offset: u64,
    capacity: u32,
    key_bits: u32,
}

/// The aligned window of a buffer that holds a u32 count, and the count's index in it: the
/// whole buffer may exceed a storage binding, and a binding's offset must be aligned.
struct CountWindow<'a> {
    buffer: &'a wgpu::Buffer,
    offset: u64,
    size: u64,
    index: u32,
}

impl<'a> CountWindow<'a> {
    fn new(ctx: &GpuContext, buffer: &'a wgpu::Buffer, count_offset: u64) -> Self {
        let alignment = u64::from(ctx.limits.min_storage_buffer_offset_alignment).max(4);
        let offset = count_offset - count_offset % alignment;
        Self {
            buffer,
            offset,
            size: count_offset - offset + 4,
            index: ((count_offset - offset) / 4) as u32,
        }
    }

    fn binding(&self) -> Binding<'a> {
        Binding::Range {
            buffer: self.buffer,
            offset: self.offset,
            size: self.size,
        }
    }
}

/// (shift, digit mask) uniforms for each pass over the low `key_bits` bits; the last pass' mask
/// drops bits at and above `key_bits`.
fn pass_param_buffers(ctx: &GpuContext, key_bits: u32) -> Vec<wgpu::Buffer> {
    (0..key_bits.div_ceil(RADIX_BITS))
        .map(|pass| {
            let shift = pass * RADIX_BITS;
            let bits = (key_bits - shift).min(RADIX_BITS);
            let params = [shift, (1u32 << bits) - 1, 0, 0];
            ctx.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("radix sort pass params"),
                    contents: bytemuck::cast_slice(&params),
                    usage: wgpu::BufferUsages::UNIFORM,
                })
        })
        .collect()
}
