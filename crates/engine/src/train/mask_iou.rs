//! The partial-mask filter's overlap counts on the GPU: per (object, view) pair, the pixels where
//! the object's render alone covers (alpha > 0.5) and its 2D mask holds it, and where either does.
//! Two u32 per pair leave the GPU instead of each object's image.

use bytemuck::{Pod, Zeroable};

use crate::render::ObjectBatchOutput;
use crate::train::partial_filter_report::PairOverlap;
use segsplat_gpu::kernel::{Kernel, workgroups_for};
use segsplat_gpu::{GpuContext, GpuError};

/// Pixels one invocation counts (`RUN` in the shader).
const PIXELS_PER_INVOCATION: u32 = 64;
const WORKGROUP: u32 = 64;

#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct IouUniforms {
    pixel_count: u32,
    slot_count: u32,
    first_pair: u32,
    _pad: u32,
}

/// Intersection and union counts for `pairs` (object, view) pairs, filled batch by batch.
pub struct MaskIouCounts {
    kernel: Kernel,
    counts: wgpu::Buffer,
    pairs: usize,
}

impl MaskIouCounts {
    pub fn new(ctx: &GpuContext, pairs: usize) -> Result<Self, GpuError> {
        Ok(Self {
            kernel: Kernel::new(
                ctx,
                "mask_iou",
                &[include_str!("mask_iou.wgsl")],
                "main",
                &[],
            )?,
            counts: ctx.storage_buffer("mask_iou.counts", pairs as u64 * 8)?,
            pairs,
        })
    }

    /// Records zeroing the counts of pairs `first..first + count` (before counting them again).
    pub fn encode_clear(&self, encoder: &mut segsplat_gpu::Encoder, first: usize, count: usize) {
        encoder.clear_buffer(&self.counts, first as u64 * 8, Some(count as u64 * 8));
    }

    /// Records counting `batch`'s slots as pairs `first_pair..` against the view's id maps
    /// (`ids[level]`, one u32 per pixel of the batch's camera). The counts add to what is there.
    pub fn encode_batch(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        batch: &ObjectBatchOutput<'_>,
        ids: [&wgpu::Buffer; 3],
        first_pair: usize,
    ) {
        let pixel_count = batch.camera.pixel_count() as u32;
        let slot_count = batch.slots.len() as u32;
        let uniforms = IouUniforms {
            pixel_count,
            slot_count,
            first_pair: first_pair as u32,
            _pad: 0,
        };
        let bind_group = self.kernel.bind_params(
            ctx,
            bytemuck::bytes_of(&uniforms),
            &[
                batch.images(),
                ids[0],
                ids[1],
                ids[2],
                batch.slot_table(),
                &self.counts,
            ],
        );
        let runs = pixel_count.div_ceil(PIXELS_PER_INVOCATION);
        self.kernel.dispatch(
            encoder,
            &bind_group,
            [workgroups_for(runs, WORKGROUP), slot_count, 1],
        );
    }

    /// Reads every pair's counts back (one read-back; waits for the recorded work).
    pub fn read_overlaps(&self, ctx: &GpuContext) -> Result<Vec<PairOverlap>, GpuError> {
        let counts: Vec<u32> = ctx.read_vec(&self.counts)?;
        Ok(counts
            .chunks_exact(2)
            .take(self.pairs)
            .map(|pair| PairOverlap {
                intersection: pair[0],
                union: pair[1],
            })
            .collect())
    }

    /// Reads every pair's IoU back (one read-back; waits for the recorded work). A pair whose
    /// render and mask are both empty scores 0.
    pub fn read_ious(&self, ctx: &GpuContext) -> Result<Vec<f32>, GpuError> {
        Ok(self
            .read_overlaps(ctx)?
            .into_iter()
            .map(PairOverlap::iou)
            .collect())
    }
}
