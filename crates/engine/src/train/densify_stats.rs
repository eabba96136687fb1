//! GPU accumulators for densification decisions, filled after each training render and read back
//! only when densifying (every `densify_interval` steps).

use bytemuck::{Pod, Zeroable};

use crate::densify::DensifyStats;
use crate::densify::gpu::StatBuffers;
use segsplat_gpu::kernel::{Kernel, workgroups_2d, workgroups_for};
use segsplat_gpu::{GpuContext, GpuError};

const WORKGROUP: u32 = 256;

#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct StatsUniforms {
    gaussian_count: u32,
    half_width: f32,
    half_height: f32,
    longer_side: f32,
}

pub struct DensifyAccumulators {
    kernel: Kernel,
    uniforms: wgpu::Buffer,
    gradient_sums: wgpu::Buffer,
    visible_counts: wgpu::Buffer,
    max_radii: wgpu::Buffer,
    capacity: usize,
}

fn storage(ctx: &GpuContext, label: &str, capacity: usize) -> Result<wgpu::Buffer, GpuError> {
    ctx.storage_buffer(label, capacity as u64 * 4)
}

impl DensifyAccumulators {
    pub fn new(ctx: &GpuContext, capacity: usize) -> Result<Self, GpuError> {
        ctx.check_binding_size("densification statistics", (capacity * 4) as u64)?;
        Ok(Self {
            kernel: Kernel::new(
                ctx,
                "densify_stats",
                &[include_str!("densify_stats.wgsl")],
                "main",
                &[],
            )?,
            uniforms: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("densify_stats.uniforms"),
                size: std::mem::size_of::<StatsUniforms>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            gradient_sums: storage(ctx, "densify.gradient_sums", capacity)?,
            visible_counts: storage(ctx, "densify.visible_counts", capacity)?,
            max_radii: storage(ctx, "densify.max_radii", capacity)?,
            capacity,
        })
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Records folding one render's statistic in. `projected` and `mean2d_abs` are the renderer's
    /// buffers for that render; `image_size` its width and height. Writes the uniforms through
    /// the encoder so it can be recorded next to other work.
    pub fn encode_accumulate(
        &self,
        ctx: &GpuContext,
        encoder: &mut segsplat_gpu::Encoder,
        projected: &wgpu::Buffer,
        mean2d_abs: &wgpu::Buffer,
        gaussian_count: u32,
        image_size: [u32; 2],
    ) {
        if gaussian_count == 0 {
            return;
        }
        let uniforms = StatsUniforms {
            gaussian_count,
            half_width: image_size[0] as f32 * 0.5,
            half_height: image_size[1] as f32 * 0.5,
            longer_side: image_size[0].max(image_size[1]) as f32,
        };
        ctx.encode_upload(encoder, bytemuck::bytes_of(&uniforms), &self.uniforms, 0);
        let bind_group = self.kernel.bind(
            ctx,
            &[
                &self.uniforms,
                projected,
                mean2d_abs,
                &self.gradient_sums,
                &self.visible_counts,
                &self.max_radii,
            ],
        );
        let groups = workgroups_for(gaussian_count, WORKGROUP);
        self.kernel.dispatch(
            encoder,
            &bind_group,
            workgroups_2d(groups, ctx.limits.max_compute_workgroups_per_dimension),
        );
    }

    /// The accumulators, for the densification pass that reads them.
    pub fn buffers(&self) -> StatBuffers<'_> {
        StatBuffers {
            gradient_sums: &self.gradient_sums,
            visible_counts: &self.visible_counts,
            max_radii: &self.max_radii,
        }
    }

    pub fn encode_clear(&self, encoder: &mut segsplat_gpu::Encoder) {
        encoder.clear_buffer(&self.gradient_sums, 0, None);
        encoder.clear_buffer(&self.visible_counts, 0, None);
        encoder.clear_buffer(&self.max_radii, 0, None);
    }

    /// Reads the first `count` entries back (a densification-time read-back).
    pub fn download(&self, ctx: &GpuContext, count: usize) -> Result<DensifyStats, GpuError> {
        let mut stats = DensifyStats {
            gradient_sums: ctx.read_vec(&self.gradient_sums)?,
            visible_counts: ctx.read_vec(&self.visible_counts)?,
            max_radii: ctx.read_vec(&self.max_radii)?,
        };
        stats.gradient_sums.truncate(count);
        stats.visible_counts.truncate(count);
        stats.max_radii.truncate(count);
        Ok(stats)
    }

    /// Restores accumulators (checkpoint resume).
    pub fn upload(&self, ctx: &GpuContext, stats: &DensifyStats) {
        ctx.queue.write_buffer(
            &self.gradient_sums,
            0,
            bytemuck::cast_slice(&stats.gradient_sums),
        );
        ctx.queue.write_buffer(
            &self.visible_counts,
            0,
            bytemuck::cast_slice(&stats.visible_counts),
        );
        ctx.queue
            .write_buffer(&self.max_radii, 0, bytemuck::cast_slice(&stats.max_radii));
    }
}
