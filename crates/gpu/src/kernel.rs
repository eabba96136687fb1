//! Compute kernel loading: WGSL sources from the `shaders/` folders beside their modules (embedded at build time), optional shared
//! snippets prepended, one pipeline per entry point with an automatic bind-group layout.
//!
//! Convention for every kernel: all bindings in `@group(0)`, numbered from 0 in the order the
//! caller passes buffers to [`Kernel::bind`]; a kernel's parameters, when it has any, are a
//! `var<uniform>` at binding 0, filled by [`Kernel::bind_params`].

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use crate::bind_cache::{BindKey, BoundRange};
use crate::kernel_cache::KernelKey;
use crate::kernel_layout::{BindingKind, layout_entries, reflect_bindings};
use crate::profiler::KernelProfiler;
use crate::uniform_ring::UniformParams;
use crate::validation::validated;
use crate::{Encoder, GpuContext, GpuError};

/// Uniform bindings a kernel may have with dynamic offsets; more keep the automatic layout.
const MAX_DYNAMIC_UNIFORMS: usize = 4;

/// Tells kernels apart in the bind-group cache.
static NEXT_KERNEL_ID: AtomicU64 = AtomicU64::new(0);

/// One compute pipeline.
#[derive(Debug, Clone)]
pub struct Kernel {
    pub pipeline: wgpu::ComputePipeline,
    label: &'static str,
    profiler: Option<Arc<KernelProfiler>>,
    layout: wgpu::BindGroupLayout,
    /// Which bindings are uniforms with a dynamic offset (empty under the automatic layout).
    dynamic_uniforms: Vec<u32>,
    id: u64,
}

/// A bind group with the dynamic offsets of its uniforms: what a dispatch binds.
#[derive(Debug, Clone)]
pub struct Bound {
    group: wgpu::BindGroup,
    offsets: [u32; MAX_DYNAMIC_UNIFORMS],
    offset_count: usize,
}

/// What goes at one binding (see [`Kernel::bind_entries`]).
#[derive(Debug, Clone, Copy)]
pub enum Binding<'a> {
    /// A whole buffer.
    Whole(&'a wgpu::Buffer),
    /// `size` bytes of a buffer from `offset` (a window of a buffer larger than a binding).
    Range {
        buffer: &'a wgpu::Buffer,
        offset: u64,
        size: u64,
    },
    /// A uniform's bytes, written to the context's uniform ring.
    Params(&'a [u8]),
    /// Parameters already pushed (several kernels binding the same ones).
    Uniform(&'a UniformParams),
}

impl Bound {
    fn dynamic_offsets(&self) -> &[u32] {
        &self.offsets[..self.offset_count]
    }
}

impl Kernel {
    /// The pipeline of `entry_point` in the concatenation of `sources` (snippets first, kernel
    /// last), compiled on first use and then reused from the context's cache (see
    /// [`crate::kernel_cache`]). `constants` fill WGSL `override` declarations (e.g. workgroup
    /// sizes). A source the device rejects is an error naming the kernel, and is not kept.
    pub fn new(
        ctx: &GpuContext,
        label: &'static str,
        sources: &[&str],
        entry_point: &str,
        constants: &[(&str, f64)],
    ) -> Result<Self, GpuError> {
        let key = KernelKey::new(label, sources.concat(), entry_point, constants);
        if let Some(kernel) = ctx.cached_kernel(&key) {
            // Profiling may have been turned on since the kernel was compiled.
            return Ok(Self {
                profiler: ctx.profiler.clone(),
                ..kernel
            });
        }
        let started = Instant::now();
        let kernel = validated(ctx, label, || {
            Self::compile(ctx, label, &key.source, entry_point, constants)
        })?;
        ctx.keep_kernel(key, kernel.clone(), started.elapsed());
        Ok(kernel)
    }

    fn compile(
        ctx: &GpuContext,
        label: &'static str,
        source: &str,
        entry_point: &str,
        constants: &[(&str, f64)],
    ) -> Self {
        let reflected = reflect_bindings(source, entry_point).filter(|bindings| {
            let uniforms = bindings
                .iter()
                .filter(|(_, kind)| *kind == BindingKind::Uniform)
                .count();
            uniforms <= MAX_DYNAMIC_UNIFORMS
        });
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        let explicit = reflected.as_ref().map(|bindings| {
            let layout = ctx
                .device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some(label),
                    entries: &layout_entries(bindings),
                });
            let pipeline_layout =
                ctx.device
                    .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some(label),
                        bind_group_layouts: &[Some(&layout)],
                        immediate_size: 0,
                    });
            (layout, pipeline_layout)
        });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: explicit
                    .as_ref()
                    .map(|(_, pipeline_layout)| pipeline_layout),
                module: &module,
                entry_point: Some(entry_point),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants,
                    zero_initialize_workgroup_memory: true,
                },
                cache: None,
            });
        let dynamic_uniforms = reflected
            .iter()
            .flatten()
            .filter(|(_, kind)| *kind == BindingKind::Uniform)
            .map(|(binding, _)| *binding)
            .collect();
        let layout = match explicit {
            Some((layout, _)) => layout,
            None => pipeline.get_bind_group_layout(0),
        };
        Self {
            pipeline,
            label,
            profiler: ctx.profiler.clone(),
            layout,
            dynamic_uniforms,
            id: NEXT_KERNEL_ID.fetch_add(1, Ordering::Relaxed),
        }
    }

    /// `buffers[i]` (whole buffer) at `@group(0) @binding(i)`. The bind group is cached on the
    /// context until these buffers are no longer bound (see [`crate::bind_cache`]).
    pub fn bind(&self, ctx: &GpuContext, buffers: &[&wgpu::Buffer]) -> Bound {
        let bindings: Vec<Binding> = buffers
            .iter()
            .map(|buffer| Binding::Whole(buffer))
            .collect();
        self.bind_entries(ctx, &bindings)
    }

    /// `params` (a uniform's bytes) at binding 0 and `buffers[i]` at binding `i + 1`.
    pub fn bind_params(&self, ctx: &GpuContext, params: &[u8], buffers: &[&wgpu::Buffer]) -> Bound {
        let mut bindings = Vec::with_capacity(buffers.len() + 1);
        bindings.push(Binding::Params(params));
        bindings.extend(buffers.iter().map(|buffer| Binding::Whole(buffer)));
        self.bind_entries(ctx, &bindings)
    }

    /// Parameters pushed earlier (shared by several kernels) at binding 0 and `buffers[i]` at
    /// binding `i + 1`.
    pub fn bind_with(
        &self,
        ctx: &GpuContext,
        params: &UniformParams,
        buffers: &[&wgpu::Buffer],
    ) -> Bound {
        let mut bindings = Vec::with_capacity(buffers.len() + 1);
        bindings.push(Binding::Uniform(params));
        bindings.extend(buffers.iter().map(|buffer| Binding::Whole(buffer)));
        self.bind_entries(ctx, &bindings)
    }

    /// `bindings[i]` at `@group(0) @binding(i)`. Parameters go into the context's uniform ring,
    /// so nothing is allocated, and the bind group is the cached one whenever the buffers are the
    /// same as in an earlier call.
    pub fn bind_entries(&self, ctx: &GpuContext, bindings: &[Binding<'_>]) -> Bound {
        let mut offsets = [0; MAX_DYNAMIC_UNIFORMS];
        let mut ranges = Vec::with_capacity(bindings.len());
        for (index, binding) in bindings.iter().enumerate() {
            let dynamic = self
                .dynamic_uniforms
                .iter()
                .position(|&uniform| uniform == index as u32);
            let range = match *binding {
                Binding::Whole(buffer) => BoundRange {
                    buffer: buffer.clone(),
                    offset: 0,
                    size: None,
                },
                Binding::Range {
                    buffer,
                    offset,
                    size,
                } => BoundRange {
                    buffer: buffer.clone(),
                    offset,
                    size: Some(size),
                },
                Binding::Params(bytes) => {
                    uniform_range(&ctx.uniform_params(bytes), dynamic, &mut offsets)
                }
                Binding::Uniform(params) => uniform_range(params, dynamic, &mut offsets),
            };
            ranges.push(range);
        }
        let key = BindKey {
            kernel: self.id,
            ranges,
        };
        let group = ctx.cached_bind_group(key, |key| {
            let entries: Vec<wgpu::BindGroupEntry> = key
                .ranges
                .iter()
                .enumerate()
                .map(|(index, range)| wgpu::BindGroupEntry {
                    binding: index as u32,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &range.buffer,
                        offset: range.offset,
                        size: range.size.and_then(wgpu::BufferSize::new),
                    }),
                })
                .collect();
            ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(self.label),
                layout: &self.layout,
                entries: &entries,
            })
        });
        Bound {
            group,
            offsets,
            offset_count: self.dynamic_uniforms.len(),
        }
    }

    fn timestamp_writes(&self, name: &'static str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        self.profiler
            .as_ref()
            .and_then(|profiler| profiler.pass_writes(name))
    }

    /// Records one dispatch of `workgroups` groups, in the encoder's open pass.
    pub fn dispatch(&self, encoder: &mut Encoder, bound: &Bound, workgroups: [u32; 3]) {
        self.dispatch_named(encoder, bound, workgroups, self.label);
    }

    /// [`Kernel::dispatch`], timed by a kernel profile under `name` instead of the kernel's
    /// label: for a kernel that does several jobs (the deformation field's GEMM does a layer's
    /// three products), so the profile says which of them takes the time.
    pub fn dispatch_named(
        &self,
        encoder: &mut Encoder,
        bound: &Bound,
        workgroups: [u32; 3],
        name: &'static str,
    ) {
        self.record(encoder, bound, name, |pass| {
            pass.dispatch_workgroups(workgroups[0], workgroups[1], workgroups[2]);
        });
    }

    /// Records one dispatch whose group counts are read on the GPU from `indirect` at `offset`
    /// (three u32), so counts computed by earlier kernels need no CPU read-back.
    pub fn dispatch_indirect(
        &self,
        encoder: &mut Encoder,
        bound: &Bound,
        indirect: &wgpu::Buffer,
        offset: u64,
    ) {
        self.record(encoder, bound, self.label, |pass| {
            pass.dispatch_workgroups_indirect(indirect, offset);
        });
    }

    /// Sets this kernel and its bindings on the encoder's shared pass, or on a pass of its own
    /// when the profiler times it (under `name`), then records the dispatch.
    fn record(
        &self,
        encoder: &mut Encoder,
        bound: &Bound,
        name: &'static str,
        dispatch: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) {
        match self.timestamp_writes(name) {
            Some(writes) => {
                let mut pass = encoder.timed_pass(name, writes);
                self.set_and_dispatch(&mut pass, bound, dispatch);
            }
            None => self.set_and_dispatch(encoder.shared_pass(), bound, dispatch),
        }
        crate::host_costs::count_dispatch_on_this_thread();
    }

    fn set_and_dispatch(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        bound: &Bound,
        dispatch: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bound.group, bound.dynamic_offsets());
        dispatch(pass);
    }
}

/// The range binding `params`: the ring at a dynamic offset when the layout has one there
/// (stored in `offsets`), else at a fixed offset (a new bind group per slot, still no buffer).
fn uniform_range(
    params: &UniformParams,
    dynamic: Option<usize>,
    offsets: &mut [u32; MAX_DYNAMIC_UNIFORMS],
) -> BoundRange {
    match (params.slot, dynamic) {
        (Some(slot), Some(dynamic)) => {
            offsets[dynamic] = slot.offset;
            BoundRange {
                buffer: params.buffer.clone(),
                offset: 0,
                size: Some(u64::from(slot.size)),
            }
        }
        (Some(slot), None) => BoundRange {
            buffer: params.buffer.clone(),
            offset: u64::from(slot.offset),
            size: Some(u64::from(slot.size)),
        },
        (None, _) => BoundRange {
            buffer: params.buffer.clone(),
            offset: 0,
            size: None,
        },
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
