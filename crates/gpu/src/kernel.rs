//! Compute kernel loading: WGSL sources from the `shaders/` folders beside their modules (embedded at build time), optional shared
//! snippets prepended, one pipeline per entry point with an automatic bind-group layout.
//!
//! Convention for every kernel: all bindings in `@group(0)`, numbered from 0 in the order the
//! caller passes buffers to [`Kernel::bind`].

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::GpuContext;
use crate::profiler::KernelProfiler;

/// One compute pipeline.
#[derive(Debug, Clone)]
pub struct Kernel {
    pub pipeline: wgpu::ComputePipeline,
    label: &'static str,
    profiler: Option<Arc<KernelProfiler>>,
    dispatches: Arc<AtomicU64>,
}

impl Kernel {
    /// Compiles `entry_point` from the concatenation of `sources` (snippets first, kernel last).
    /// `constants` fill WGSL `override` declarations (e.g. workgroup sizes).
    pub fn new(
        ctx: &GpuContext,
        label: &'static str,
        sources: &[&str],
        entry_point: &str,
        constants: &[(&str, f64)],
    ) -> Self {
        let source = sources.concat();
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: None,
                module: &module,
                entry_point: Some(entry_point),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants,
                    zero_initialize_workgroup_memory: true,
                },
                cache: None,
            });
        Self {
            pipeline,
            label,
            profiler: ctx.profiler.clone(),
            dispatches: Arc::clone(&ctx.dispatches),
        }
    }

    /// A bind group with `buffers[i]` (whole buffer) at `@group(0) @binding(i)`.
    pub fn bind(&self, ctx: &GpuContext, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(index, buffer)| wgpu::BindGroupEntry {
                binding: index as u32,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }

    fn timestamp_writes(&self) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        self.profiler
            .as_ref()
            .and_then(|profiler| profiler.pass_writes(self.label))
    }

    /// Records one dispatch of `workgroups` groups.
    pub fn dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        workgroups: [u32; 3],
    ) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(self.label),
            timestamp_writes: self.timestamp_writes(),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(workgroups[0], workgroups[1], workgroups[2]);
        self.dispatches.fetch_add(1, Ordering::Relaxed);
    }

    /// Records one dispatch whose group counts are read on the GPU from `indirect` at `offset`
    /// (three u32), so counts computed by earlier kernels need no CPU read-back.
    pub fn dispatch_indirect(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        indirect: &wgpu::Buffer,
        offset: u64,
    ) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(self.label),
            timestamp_writes: self.timestamp_writes(),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups_indirect(indirect, offset);
        self.dispatches.fetch_add(1, Ordering::Relaxed);
    }
}

/// WGSL declarations of constants the host uses too, prepended to the kernels that need them,
/// so each has one source: the Rust constant.
pub fn wgsl_u32_constants(constants: &[(&str, u32)]) -> String {
    constants
        .iter()
        .map(|(name, value)| format!("const {name}: u32 = {value}u;\n"))
        .collect()
}

/// Workgroups needed to cover `items` with groups of `group_size` (at least one).
pub fn workgroups_for(items: u32, group_size: u32) -> u32 {
    items.div_ceil(group_size).max(1)
}

/// Splits a large 1D group count over x and y so it stays within the 65535-per-dimension limit;
/// kernels recover the flat index as `gid.x + gid.y * num_workgroups.x * group_size`.
pub fn workgroups_2d(groups: u32, max_per_dim: u32) -> [u32; 3] {
    if groups <= max_per_dim {
        [groups.max(1), 1, 1]
    } else {
        [max_per_dim, groups.div_ceil(max_per_dim), 1]
    }
}
