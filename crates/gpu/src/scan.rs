//! Exclusive prefix sum of u32 on the GPU.
//!
//! Multi-level: level 0 scans blocks of [`SCAN_BLOCK_ELEMENTS`] and writes block totals, the next
//! level scans those totals, and so on until one block holds a level; then each level adds the
//! scanned totals of the level above back into its blocks. Three levels cover a billion elements.
//!
//! Per-level element counts are read by the kernels from a small storage buffer, so the same
//! kernels serve a count known on the CPU ([`ExclusiveScan::encode`]) and a count only known on the
//! GPU (the radix sort scans histograms whose size a plan kernel computes; see [`ScanDispatch`]).

use std::sync::Mutex;

use wgpu::util::DeviceExt;

use crate::kernel::{wgsl_u32_constants, workgroups_2d};
use crate::{GpuContext, GpuError, Kernel};

/// Elements one workgroup scans (prepended to the scan kernels as `SCAN_BLOCK`).
pub const SCAN_BLOCK_ELEMENTS: u32 = 1024;
/// Levels the level-count layout has room for (1024^4 elements).
pub(crate) const MAX_SCAN_LEVELS: usize = 4;
/// Where level 0's counts start in a level-counts buffer; the first two slots are free for the
/// caller (the radix sort keeps its element and block counts there).
const FIRST_LEVEL_COUNTS_INDEX: u32 = 2;
/// u32 slots in a level-counts buffer.
pub(crate) const LEVEL_COUNTS_LEN: usize = FIRST_LEVEL_COUNTS_INDEX as usize + 2 * MAX_SCAN_LEVELS;

const SCAN_COMMON: &str = include_str!("shaders/scan_common.wgsl");

/// `SCAN_BLOCK` for the scan kernels and the sort's plan kernel, from [`SCAN_BLOCK_ELEMENTS`].
pub(crate) fn block_constant() -> String {
    wgsl_u32_constants(&[("SCAN_BLOCK", SCAN_BLOCK_ELEMENTS)])
}
const WORKGROUP_SUM_SHARED: &str = include_str!("shaders/workgroup_sum_shared.wgsl");
const WORKGROUP_SUM_SUBGROUPS: &str = include_str!("shaders/workgroup_sum_subgroups.wgsl");
const SCAN_BLOCKS: &str = include_str!("shaders/scan_blocks.wgsl");
const SCAN_ADD: &str = include_str!("shaders/scan_add.wgsl");

/// How the scan and the radix sort add up one value per thread over a workgroup.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WorkgroupSum {
    /// In workgroup memory, log2(threads) rounds of two barriers (`workgroup_sum_shared.wgsl`).
    SharedMemory,
    /// By subgroup scans and two barriers (`workgroup_sum_subgroups.wgsl`): software adapters
    /// with subgroups, where each barrier switches between every subgroup of the workgroup.
    Subgroups,
}

impl WorkgroupSum {
    pub fn for_adapter(ctx: &GpuContext) -> Self {
        if ctx.report.is_software && ctx.has_subgroups() {
            Self::Subgroups
        } else {
            Self::SharedMemory
        }
    }

    /// Every way the adapter can run.
    pub fn supported(ctx: &GpuContext) -> Vec<Self> {
        if ctx.has_subgroups() {
            vec![Self::SharedMemory, Self::Subgroups]
        } else {
            vec![Self::SharedMemory]
        }
    }

    /// The WGSL defining `workgroup_exclusive_sum`.
    pub(crate) fn source(self) -> &'static str {
        match self {
            Self::SharedMemory => WORKGROUP_SUM_SHARED,
            Self::Subgroups => WORKGROUP_SUM_SUBGROUPS,
        }
    }
}

/// Index of level `level`'s `[input count, output count]` pair in a level-counts buffer.
pub(crate) const fn level_counts_index(level: usize) -> u32 {
    FIRST_LEVEL_COUNTS_INDEX + 2 * level as u32
}

/// Output counts per level for scanning `count` inputs into `count + 1` outputs (the last output
/// being the total). Level 0 is first; the last level fits in one block.
pub(crate) fn level_output_counts(count: u32) -> Vec<u32> {
    levels_from(count.saturating_add(1))
}

/// Output counts per level for scanning `count` inputs into `count` outputs, without the total
/// (the radix sort's histograms): 1024 inputs then need one level, not two.
pub(crate) fn level_output_counts_without_total(count: u32) -> Vec<u32> {
    levels_from(count.max(1))
}

fn levels_from(outputs: u32) -> Vec<u32> {
    let mut counts = vec![outputs];
    while let Some(&last) = counts.last() {
        if last <= SCAN_BLOCK_ELEMENTS {
            break;
        }
        counts.push(last.div_ceil(SCAN_BLOCK_ELEMENTS));
    }
    counts
}

/// The level-counts buffer contents for a CPU-known `count`.
fn level_counts_for(count: u32) -> [u32; LEVEL_COUNTS_LEN] {
    let mut counts = [0u32; LEVEL_COUNTS_LEN];
    for (level, &output_count) in level_output_counts(count).iter().enumerate() {
        let index = level_counts_index(level) as usize;
        counts[index] = if level == 0 { count } else { output_count };
        counts[index + 1] = output_count;
    }
    counts
}

/// Block totals of levels 1 and up: `totals[level - 1]` is written by level `level - 1`, scanned
/// into `scanned[level - 1]`. Grows, never shrinks.
#[derive(Debug, Default)]
pub(crate) struct ScanScratch {
    totals: Vec<wgpu::Buffer>,
    scanned: Vec<wgpu::Buffer>,
}

impl ScanScratch {
    /// Makes room for scans whose levels have (at most) `output_counts`.
    pub(crate) fn reserve(&mut self, ctx: &GpuContext, output_counts: &[u32]) {
        for (level, &count) in output_counts.iter().enumerate().skip(1) {
            let bytes = u64::from(count) * 4;
            let slot = level - 1;
            if self
                .totals
                .get(slot)
                .is_some_and(|buffer| buffer.size() >= bytes)
            {
                continue;
            }
            let make = |label| {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes,
                    usage: wgpu::BufferUsages::STORAGE,
                    mapped_at_creation: false,
                })
            };
            let (totals, scanned) = (make("scan block totals"), make("scan block offsets"));
            if slot < self.totals.len() {
                self.totals[slot] = totals;
                self.scanned[slot] = scanned;
            } else {
                self.totals.push(totals);
                self.scanned.push(scanned);
            }
        }
    }
}

/// Where a scan's level counts and block totals live, and how its kernels are dispatched.
pub(crate) struct ScanLevels<'a> {
    /// Per-level counts (layout: [`level_counts_index`]).
    pub(crate) level_counts: &'a wgpu::Buffer,
    /// Block totals, already reserved for these levels.
    pub(crate) scratch: &'a ScanScratch,
    pub(crate) dispatch: ScanDispatch<'a>,
}

/// How the level kernels get their workgroup counts.
pub(crate) enum ScanDispatch<'a> {
    /// Output counts per level, known on the CPU.
    Direct(&'a [u32]),
    /// `levels` levels whose group counts a plan kernel wrote to `args` (three u32 per level,
    /// level 0 at `first_offset_bytes`).
    Indirect {
        args: &'a wgpu::Buffer,
        first_offset_bytes: u64,
        levels: usize,
    },
}

impl ScanDispatch<'_> {
    fn levels(&self) -> usize {
        match self {
            ScanDispatch::Direct(counts) => counts.len(),
            ScanDispatch::Indirect { levels, .. } => *levels,
        }
    }
}

/// Exclusive scan of u32 (see the module doc).
#[derive(Debug)]
pub struct ExclusiveScan {
    scan_blocks: Kernel,
    add_block_offsets: Kernel,
    /// One uniform per level telling the kernels where that level's counts are.
    level_params: Vec<wgpu::Buffer>,
    /// Bound as input when the caller's input buffer is empty (count 0).
    empty_input: wgpu::Buffer,
    /// Bound as the top level's block-total output, which nothing reads.
    unused_totals: wgpu::Buffer,
    scratch: Mutex<ScanScratch>,
    /// The level counts of [`ExclusiveScan::encode`], written through the encoder per scan.
    level_counts: wgpu::Buffer,
}

impl ExclusiveScan {
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        Self::with_sum(ctx, WorkgroupSum::for_adapter(ctx))
    }

    /// A scan whose blocks add up their threads' totals the given way.
    pub fn with_sum(ctx: &GpuContext, sum: WorkgroupSum) -> Result<Self, GpuError> {
        let scan_blocks = Kernel::new(
            ctx,
            "scan_blocks",
            &[&block_constant(), SCAN_COMMON, sum.source(), SCAN_BLOCKS],
            "scan_blocks",
            &[],
        )?;
        let add_block_offsets = Kernel::new(
            ctx,
            "add_block_offsets",
            &[&block_constant(), SCAN_COMMON, SCAN_ADD],
            "add_block_offsets",
            &[],
        )?;
        let level_params = (0..MAX_SCAN_LEVELS)
            .map(|level| {
                let params = [level_counts_index(level), 0, 0, 0];
                ctx.device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("scan level params"),
                        contents: bytemuck::cast_slice(&params),
                        usage: wgpu::BufferUsages::UNIFORM,
                    })
            })
            .collect();
        let placeholder = |label| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        Ok(Self {
            scan_blocks,
            add_block_offsets,
            level_params,
            empty_input: placeholder("scan empty input"),
            unused_totals: placeholder("scan unused totals"),
            scratch: Mutex::new(ScanScratch::default()),
            level_counts: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("scan level counts"),
                size: (LEVEL_COUNTS_LEN * 4) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        })
    }

    /// output[i] = input[0] + ... + input[i-1] for i in 0..=count: `output` holds count + 1 u32,
    /// the last being the total. `count` is known on the CPU. input and output must not alias.
    /// Sums wrap modulo 2^32.
    pub fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut crate::Encoder,
        input: &wgpu::Buffer,
        output: &wgpu::Buffer,
        count: u32,
    ) {
        debug_assert!(input.size() >= u64::from(count) * 4, "scan input too small");
        debug_assert!(
            output.size() >= (u64::from(count) + 1) * 4,
            "scan output needs count + 1 elements"
        );
        let output_counts = level_output_counts(count);
        // Through the encoder: several scans recorded before one submission each see theirs.
        ctx.encode_upload(
            encoder,
            bytemuck::cast_slice(&level_counts_for(count)),
            &self.level_counts,
            0,
        );
        // A poisoned lock only means another encode panicked; the scratch buffers are still valid.
        let mut scratch = self
            .scratch
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        scratch.reserve(ctx, &output_counts);
        let levels = ScanLevels {
            level_counts: &self.level_counts,
            scratch: &scratch,
            dispatch: ScanDispatch::Direct(&output_counts),
        };
        self.encode_levels(ctx, encoder, input, output, &levels);
    }

    /// Records all levels of a scan of `input` into `output`.
    pub(crate) fn encode_levels(
        &self,
        ctx: &GpuContext,
        encoder: &mut crate::Encoder,
        input: &wgpu::Buffer,
        output: &wgpu::Buffer,
        levels_plan: &ScanLevels<'_>,
    ) {
        let ScanLevels {
            level_counts,
            scratch,
            dispatch,
        } = levels_plan;
        let levels = dispatch.levels().clamp(1, MAX_SCAN_LEVELS);
        let input = if input.size() < 4 {
            &self.empty_input
        } else {
            input
        };
        let level_input = |level: usize| {
            if level == 0 {
                input
            } else {
                &scratch.totals[level - 1]
            }
        };
        let level_output = |level: usize| {
            if level == 0 {
                output
            } else {
                &scratch.scanned[level - 1]
            }
        };
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension;
        let run = |kernel: &Kernel,
                   encoder: &mut crate::Encoder,
                   bind_group: &crate::Bound,
                   level: usize| match dispatch {
            ScanDispatch::Direct(counts) => {
                let groups = counts[level].div_ceil(SCAN_BLOCK_ELEMENTS);
                kernel.dispatch(encoder, bind_group, workgroups_2d(groups, max_groups));
            }
            ScanDispatch::Indirect {
                args,
                first_offset_bytes,
                ..
            } => {
                let offset = first_offset_bytes + 12 * level as u64;
                kernel.dispatch_indirect(encoder, bind_group, args, offset);
            }
        };
        for level in 0..levels {
            let totals = if level + 1 < levels {
                &scratch.totals[level]
            } else {
                &self.unused_totals
            };
            let bind_group = self.scan_blocks.bind(
                ctx,
                &[
                    level_counts,
                    &self.level_params[level],
                    level_input(level),
                    level_output(level),
                    totals,
                ],
            );
            run(&self.scan_blocks, encoder, &bind_group, level);
        }
        for level in (0..levels.saturating_sub(1)).rev() {
            let bind_group = self.add_block_offsets.bind(
                ctx,
                &[
                    level_counts,
                    &self.level_params[level],
                    level_output(level),
                    &scratch.scanned[level],
                ],
            );
            run(&self.add_block_offsets, encoder, &bind_group, level);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_end_with_one_block() {
        assert_eq!(level_output_counts(0), vec![1]);
        assert_eq!(level_output_counts(1023), vec![1024]);
        assert_eq!(level_output_counts(1024), vec![1025, 2]);
        assert_eq!(level_output_counts(1_000_000), vec![1_000_001, 977]);
        assert_eq!(
            level_output_counts(30_000_000),
            vec![30_000_001, 29_297, 29]
        );
        assert_eq!(level_output_counts_without_total(0), vec![1]);
        assert_eq!(level_output_counts_without_total(1024), vec![1024]);
        assert_eq!(level_output_counts_without_total(1025), vec![1025, 2]);
    }
}
