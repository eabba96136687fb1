//! Adapter discovery and device creation.
//!
//! Every adapter wgpu can see is reported (name, backend, type, the limits and features the engine
//! cares about) so operators can tell at start which GPU a worker got. Devices are created with the
//! adapter's own limits (the engine sizes buffers against them, e.g. lavapipe's 128 MiB storage
//! bindings) and with the optional features the kernels exploit when present: native f32 atomics and
//! subgroups. Kernels fall back to CAS loops / shared memory when they are absent.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use serde::Serialize;

use crate::Kernel;
use crate::bind_cache::{BindGroupCache, BindKey};
use crate::host_costs::{Cost, HostCosts};
use crate::kernel_cache::{KernelCache, KernelCompiles, KernelKey};
use crate::kernel_choices::KernelChoices;
use crate::uniform_ring::{UniformParams, UniformRing, this_thread};
use wgpu::util::DeviceExt;

use super::profiler::KernelProfiler;

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter matches {filter} (found: {found})")]
    NoAdapter { filter: String, found: String },
    #[error("adapter {adapter:?} refused a device: {source}")]
    RequestDevice {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
    #[error("GPU poll failed: {0}")]
    Poll(#[from] wgpu::PollError),
    #[error("GPU buffer mapping failed: {0}")]
    Map(#[from] wgpu::BufferAsyncError),
    #[error("GPU reported an error: {0}")]
    Device(String),
    #[error(
        "{what} needs {needed_bytes} bytes in one storage binding but the adapter allows {limit_bytes}"
    )]
    BindingTooLarge {
        what: String,
        needed_bytes: u64,
        limit_bytes: u64,
    },
    #[error("the adapter cannot run this: {0}")]
    Unsupported(String),
}

/// Which adapters a worker may use, and how to open them. Empty fields match everything.
#[derive(Debug, Clone, Default, serde::Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdapterFilter {
    /// Case-insensitive substring of the adapter name (e.g. "nvidia", "llvmpipe").
    pub name_contains: Option<String>,
    /// Backends by name: "vulkan", "metal", "dx12", "gl".
    pub backends: Vec<String>,
    /// Include software (CPU) adapters. Used anyway when no hardware adapter matches.
    pub allow_software: Option<bool>,
    /// Kernel variants to force on the opened adapters, for comparisons (default: each
    /// adapter's own).
    pub kernels: KernelChoices,
}

impl AdapterFilter {
    fn matches(&self, info: &wgpu::AdapterInfo) -> bool {
        let name_ok = self
            .name_contains
            .as_ref()
            .is_none_or(|needle| info.name.to_lowercase().contains(&needle.to_lowercase()));
        let backend = backend_name(info.backend);
        let backend_ok = self.backends.is_empty()
            || self
                .backends
                .iter()
                .any(|b| b.eq_ignore_ascii_case(backend));
        name_ok && backend_ok
    }

    fn describe(&self) -> String {
        format!(
            "name_contains={:?} backends={:?}",
            self.name_contains, self.backends
        )
    }
}

/// What an adapter offers, as logged at start and served by `/readyz`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct AdapterReport {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub driver: String,
    pub is_software: bool,
    pub max_storage_buffer_binding_bytes: u64,
    pub max_buffer_bytes: u64,
    pub max_compute_workgroup_storage_bytes: u32,
    pub max_compute_invocations_per_workgroup: u32,
    pub float32_atomics: bool,
    pub subgroups: bool,
    /// Smallest and largest subgroup the adapter may run (kernels that rely on one lane count,
    /// like the deformation field's broadcast GEMM, check both).
    pub subgroup_sizes: [u32; 2],
    pub timestamp_queries: bool,
}

impl AdapterReport {
    fn new(adapter: &wgpu::Adapter) -> Self {
        let info = adapter.get_info();
        let limits = adapter.limits();
        let features = adapter.features();
        Self {
            name: info.name.clone(),
            backend: backend_name(info.backend).to_string(),
            device_type: format!("{:?}", info.device_type),
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_string(),
            is_software: info.device_type == wgpu::DeviceType::Cpu,
            max_storage_buffer_binding_bytes: limits.max_storage_buffer_binding_size,
            max_buffer_bytes: limits.max_buffer_size,
            max_compute_workgroup_storage_bytes: limits.max_compute_workgroup_storage_size,
            max_compute_invocations_per_workgroup: limits.max_compute_invocations_per_workgroup,
            float32_atomics: features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC),
            subgroups: features.contains(wgpu::Features::SUBGROUP),
            subgroup_sizes: [info.subgroup_min_size, info.subgroup_max_size],
            timestamp_queries: features.contains(wgpu::Features::TIMESTAMP_QUERY),
        }
    }
}

fn backend_name(backend: wgpu::Backend) -> &'static str {
    match backend {
        wgpu::Backend::Vulkan => "vulkan",
        wgpu::Backend::Metal => "metal",
        wgpu::Backend::Dx12 => "dx12",
        wgpu::Backend::Gl => "gl",
        wgpu::Backend::BrowserWebGpu => "webgpu",
        _ => "other",
    }
}

/// Vulkan, Metal and DX12 only (unless `WGPU_BACKEND` names others): the kernels need storage
/// buffers with atomics and subgroups that no OpenGL adapter offers, and probing the GL backend
/// on a headless Linux host makes libwayland print `XDG_RUNTIME_DIR is invalid or not set` on
/// every start, burying real errors.
fn new_instance() -> wgpu::Instance {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
    descriptor.backends = wgpu::Backends::PRIMARY;
    wgpu::Instance::new(descriptor.with_env())
}

/// All adapters wgpu can see, hardware first.
pub fn enumerate_adapters() -> Vec<(wgpu::Adapter, AdapterReport)> {
    let instance = new_instance();
    let mut adapters: Vec<_> =
        pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
            .into_iter()
            .map(|adapter| {
                let report = AdapterReport::new(&adapter);
                (adapter, report)
            })
            .collect();
    adapters.sort_by_key(|(_, report)| report.is_software);
    adapters
}

/// Adapters the filter admits. Software adapters are admitted when the filter allows them, or when
/// no hardware adapter matched (so a GPU-less machine still works, on lavapipe).
pub fn select_adapters(filter: &AdapterFilter) -> Vec<(wgpu::Adapter, AdapterReport)> {
    let matching: Vec<_> = enumerate_adapters()
        .into_iter()
        .filter(|(adapter, _)| filter.matches(&adapter.get_info()))
        .collect();
    let any_hardware = matching.iter().any(|(_, report)| !report.is_software);
    let allow_software = filter.allow_software.unwrap_or(!any_hardware);
    matching
        .into_iter()
        .filter(|(_, report)| !report.is_software || allow_software)
        .collect()
}

/// A device and queue on one adapter, with what the kernels need to know about it.
#[derive(Debug, Clone)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub report: AdapterReport,
    pub limits: wgpu::Limits,
    pub features: wgpu::Features,
    /// Per-kernel timestamps, when turned on by [`GpuContext::enable_kernel_profiling`].
    pub profiler: Option<Arc<KernelProfiler>>,
    /// Variants forced instead of the adapter's own (see [`KernelChoices`]).
    pub kernel_choices: KernelChoices,
    /// Read-backs and waits of every caller on this context: on a fast GPU the host's waits,
    /// not the kernels, bound a step, so benchmarks and jobs report them.
    pub host_costs: Arc<HostCosts>,
    /// Kernel parameters, written once per submission (see [`crate::uniform_ring`]).
    pub(crate) uniforms: Arc<Mutex<UniformRing>>,
    /// Bind groups reused while their buffers are (see [`crate::bind_cache`]).
    pub(crate) bind_groups: Arc<Mutex<BindGroupCache>>,
    /// Every kernel compiled on this device (see [`crate::kernel_cache`]).
    pub(crate) kernels: Arc<Mutex<KernelCache>>,
}

/// A lock that a panic elsewhere did not make unusable: the ring and the cache hold no invariant
/// a half-finished update could break.
fn locked<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl GpuContext {
    /// The first adapter the filter admits (hardware preferred).
    pub fn new(filter: &AdapterFilter) -> Result<Self, GpuError> {
        let mut adapters = select_adapters(filter);
        if adapters.is_empty() {
            let found: Vec<String> = enumerate_adapters()
                .into_iter()
                .map(|(_, r)| format!("{} ({})", r.name, r.backend))
                .collect();
            return Err(GpuError::NoAdapter {
                filter: filter.describe(),
                found: if found.is_empty() {
                    "none".to_string()
                } else {
                    found.join(", ")
                },
            });
        }
        let (adapter, _) = adapters.remove(0);
        Ok(Self::from_adapter(&adapter)?.with_kernel_choices(filter.kernels))
    }

    /// wgpu's no-op device: every kernel is compiled, every dispatch recorded, validated and
    /// submitted, and copies, clears and buffer writes are carried out in host memory, but no
    /// kernel runs. Training on it measures the host's side of a step alone (segsplat, wgpu-core
    /// and its resource tracking), as on a GPU whose work took no time: the floor a real
    /// device's step cannot go under, free of a software adapter's arithmetic competing for the
    /// same cores (`segsplat bench --noop-device`, docs/benchmarks.md). What it renders and
    /// trains is meaningless (every kernel's output stays zero).
    pub fn new_noop() -> Result<Self, GpuError> {
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
        descriptor.backends = wgpu::Backends::NOOP;
        // Shaped like the GPU jobs ran on (the H200's limits and 32-lane subgroups, a discrete
        // device), so the kernels and sizes chosen for it are a GPU's, not the no-op backend's
        // unlimited ones (it allocates host memory for every buffer it is asked for).
        descriptor.backend_options.noop = wgpu::NoopBackendOptions {
            enable: true,
            device_type: Some(wgpu::DeviceType::DiscreteGpu),
            subgroup_min_size: Some(32),
            subgroup_max_size: Some(32),
            limits: Some(wgpu::Limits {
                max_storage_buffer_binding_size: 2_147_483_644,
                max_buffer_size: 4_292_870_144,
                max_compute_workgroup_storage_size: 49_152,
                max_compute_invocations_per_workgroup: 1024,
                max_compute_workgroup_size_x: 1024,
                max_compute_workgroup_size_y: 1024,
                max_storage_buffers_per_shader_stage: 16,
                ..wgpu::Limits::default()
            }),
            features: None,
        };
        let instance = wgpu::Instance::new(descriptor);
        let adapter = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::NOOP))
            .into_iter()
            .next()
            .ok_or_else(|| GpuError::NoAdapter {
                filter: "the no-op backend".to_string(),
                found: "none".to_string(),
            })?;
        let mut ctx = Self::from_adapter(&adapter)?;
        // wgpu 30's no-op adapter reports itself a CPU whatever `device_type` says; the kernels
        // and sizes chosen from the report must be a GPU's.
        ctx.report.is_software = false;
        ctx.report.device_type = format!("{:?}", wgpu::DeviceType::DiscreteGpu);
        Ok(ctx)
    }

    /// Any adapter at all; what tests and the CLI use.
    pub fn new_default() -> Result<Self, GpuError> {
        Self::new(&AdapterFilter::default())
    }

    pub fn from_adapter(adapter: &wgpu::Adapter) -> Result<Self, GpuError> {
        let report = AdapterReport::new(adapter);
        let wanted = wgpu::Features::SHADER_FLOAT32_ATOMIC
            | wgpu::Features::SUBGROUP
            | wgpu::Features::TIMESTAMP_QUERY;
        let features = adapter.features() & wanted;
        let limits = adapter.limits();
        let descriptor = wgpu::DeviceDescriptor {
            label: Some("segsplat"),
            required_features: features,
            required_limits: limits.clone(),
            memory_hints: wgpu::MemoryHints::Performance,
            ..Default::default()
        };
        let (device, queue) =
            pollster::block_on(adapter.request_device(&descriptor)).map_err(|source| {
                GpuError::RequestDevice {
                    adapter: report.name.clone(),
                    source,
                }
            })?;
        let uniforms = UniformRing::new(&device, &limits);
        Ok(Self {
            uniforms: Arc::new(Mutex::new(uniforms)),
            bind_groups: Arc::new(Mutex::new(BindGroupCache::default())),
            kernels: Arc::new(Mutex::new(KernelCache::default())),
            device,
            queue,
            report,
            limits,
            features,
            profiler: None,
            kernel_choices: KernelChoices::default(),
            host_costs: Arc::new(HostCosts::default()),
        })
    }

    /// This context with a uniform ring of `bytes` (not [`crate::uniform_ring::RING_BYTES`]):
    /// tests lap a small one to check that no thread's parameters are overwritten before it
    /// submits. Call it before recording anything.
    pub fn with_uniform_ring_bytes(mut self, bytes: u64) -> Self {
        self.uniforms = Arc::new(Mutex::new(UniformRing::with_capacity(
            &self.device,
            &self.limits,
            bytes,
        )));
        self
    }

    /// Threads whose pushed kernel parameters are still protected (pushed since their last
    /// submission): 0 when every thread submitted what it recorded.
    pub fn uniform_ring_open_threads(&self) -> usize {
        locked(&self.uniforms).open_threads()
    }

    /// Times every pass of the kernels built on this context from now on (see
    /// [`KernelProfiler`]); fails when the adapter has no timestamp queries.
    pub fn enable_kernel_profiling(&mut self) -> Result<(), GpuError> {
        self.profiler = Some(Arc::new(KernelProfiler::new(self)?));
        Ok(())
    }

    pub fn has_float32_atomics(&self) -> bool {
        self.features
            .contains(wgpu::Features::SHADER_FLOAT32_ATOMIC)
    }

    /// This context with `choices` forced (the kernels built on it afterwards follow them).
    pub fn with_kernel_choices(mut self, choices: KernelChoices) -> Self {
        self.kernel_choices = choices;
        self
    }

    pub fn has_subgroups(&self) -> bool {
        self.features.contains(wgpu::Features::SUBGROUP)
    }

    /// Fails with a message naming `what` when `bytes` exceed one storage binding.
    pub fn check_binding_size(&self, what: &str, bytes: u64) -> Result<(), GpuError> {
        let limit = self.limits.max_storage_buffer_binding_size;
        if bytes > limit {
            return Err(GpuError::BindingTooLarge {
                what: what.to_string(),
                needed_bytes: bytes,
                limit_bytes: limit,
            });
        }
        Ok(())
    }

    /// A storage buffer of at least `bytes` (never empty, so it always binds) that can be copied
    /// to and from, after checking that it fits one binding. Every GPU array of the engine is
    /// one of these.
    pub fn storage_buffer(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer, GpuError> {
        self.storage_buffer_with_usage(label, bytes, wgpu::BufferUsages::empty())
    }

    /// [`Self::storage_buffer`] with `extra` usages (e.g. `INDIRECT`).
    pub fn storage_buffer_with_usage(
        &self,
        label: &str,
        bytes: u64,
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        let bytes = bytes.max(16);
        self.check_binding_size(label, bytes)?;
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST
                | extra,
            mapped_at_creation: false,
        }))
    }

    /// Submits `commands`, timing the call into [`Self::host_costs`] (the training loop's
    /// submissions go through here, so a step's host time can be told from its device time).
    pub fn submit(&self, commands: wgpu::CommandBuffer) -> wgpu::SubmissionIndex {
        let started = std::time::Instant::now();
        let submission = self.submit_untimed(commands);
        let took = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.host_costs.add(Cost::SubmitNanos, took);
        submission
    }

    /// Submits with the kernel parameters pushed so far written first. Every submission of work
    /// recorded with [`crate::Kernel`]s must come through here (or [`Self::submit`]), never
    /// `queue.submit`, or it reads parameters that were never written.
    ///
    /// The ring stays locked until the queue has the commands: a slot this thread no longer
    /// protects must not be overwritten and written by another thread's submission first.
    pub fn submit_untimed(&self, commands: wgpu::CommandBuffer) -> wgpu::SubmissionIndex {
        let mut ring = locked(&self.uniforms);
        ring.before_submit(&self.queue, this_thread());
        let submission = self.queue.submit([commands]);
        drop(ring);
        locked(&self.bind_groups).after_submit();
        submission
    }

    /// `bytes` as kernel parameters: appended to the uniform ring (written at the next
    /// submission), or, when the ring is full, in a buffer of their own (counted).
    pub fn uniform_params(&self, bytes: &[u8]) -> UniformParams {
        let mut ring = locked(&self.uniforms);
        if let Some(pushed) = ring.push(&self.queue, this_thread(), bytes) {
            let buffer = ring.buffer().clone();
            drop(ring);
            if pushed.opened {
                crate::uniform_ring::release_when_thread_ends(&self.uniforms);
            }
            return UniformParams {
                buffer,
                slot: Some(pushed.slot),
            };
        }
        drop(ring);
        self.count_buffer_created();
        let padded = bytes.len().max(16).next_multiple_of(16);
        let mut contents = bytes.to_vec();
        contents.resize(padded, 0);
        UniformParams {
            buffer: self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("kernel parameters"),
                    contents: &contents,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_SRC,
                }),
            slot: None,
        }
    }

    /// Records a copy of `bytes` into `target` at `offset` in the encoder's order, through the
    /// uniform ring (no staging buffer): for data several renders in one encoder each need
    /// their own copy of. `bytes.len()` must be a multiple of 4.
    pub fn encode_upload(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bytes: &[u8],
        target: &wgpu::Buffer,
        offset: u64,
    ) {
        let params = self.uniform_params(bytes);
        let source_offset = params.slot.map_or(0, |slot| u64::from(slot.offset));
        encoder.copy_buffer_to_buffer(
            &params.buffer,
            source_offset,
            target,
            offset,
            bytes.len() as u64,
        );
    }

    /// The kernel compiled on this device under `key`, if one was.
    pub(crate) fn cached_kernel(&self, key: &KernelKey) -> Option<Kernel> {
        locked(&self.kernels).reuse(key)
    }

    /// Keeps a kernel compiled (and validated) in `took` for later builders.
    pub(crate) fn keep_kernel(&self, key: KernelKey, kernel: Kernel, took: Duration) {
        locked(&self.kernels).insert(key, kernel, took);
    }

    /// Kernels compiled on this device so far, kernels reused instead, and the compiles' time:
    /// a trainer built on a warm context compiles nothing.
    pub fn kernel_compiles(&self) -> KernelCompiles {
        locked(&self.kernels).compiles()
    }

    /// The cached bind group for `key`, or the one `create` makes.
    pub(crate) fn cached_bind_group(
        &self,
        key: BindKey,
        create: impl FnOnce(&BindKey) -> wgpu::BindGroup,
    ) -> wgpu::BindGroup {
        let (group, created) = locked(&self.bind_groups).get_or_create(key, create);
        if created {
            self.host_costs.add(Cost::BindGroupsCreated, 1);
        }
        group
    }

    /// Counts a buffer made on a path that should make none (a training step), so benchmarks
    /// and tests can see it.
    pub fn count_buffer_created(&self) {
        self.host_costs.add(Cost::BuffersCreated, 1);
    }

    /// Drops every cached bind group, releasing buffers only they still held: for callers that
    /// free large buffers and then go idle (no submissions to age the cache).
    pub fn release_cached_bind_groups(&self) {
        locked(&self.bind_groups).clear();
    }

    /// Blocks until all submitted work is done.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        let started = std::time::Instant::now();
        let polled = self.device.poll(wgpu::PollType::wait_indefinitely());
        let waited = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.host_costs.add(Cost::WaitNanos, waited);
        polled?;
        Ok(())
    }

    /// Copies `buffer[..size_bytes]` to the CPU (a staging copy, submit, map, wait).
    /// For tests, checkpoints and the few unavoidable read-backs; never inside a training step.
    pub fn read_buffer(&self, buffer: &wgpu::Buffer, size_bytes: u64) -> Result<Vec<u8>, GpuError> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: size_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size_bytes);
        self.submit_untimed(encoder.finish());
        let slice = staging.slice(..);
        let (sender, receiver) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |result| {
            let _ = sender.send(result);
        });
        self.wait_idle()?;
        receiver
            .recv()
            .map_err(|_| GpuError::Device("map callback dropped".to_string()))??;
        let bytes = slice
            .get_mapped_range()
            .map_err(|error| GpuError::Device(format!("mapping the read-back buffer: {error}")))?
            .to_vec();
        staging.unmap();
        self.count_read_back(size_bytes);
        Ok(bytes)
    }

    /// Counts a read-back of `bytes` in the host costs (for read-backs made elsewhere, e.g.
    /// [`crate::deferred_read::DeferredRead`]).
    pub fn count_read_back(&self, bytes: u64) {
        self.host_costs.add(Cost::ReadBacks, 1);
        self.host_costs.add(Cost::BytesReadBack, bytes);
    }

    /// Typed read-back of a whole buffer of plain values.
    pub fn read_vec<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer) -> Result<Vec<T>, GpuError> {
        let bytes = self.read_buffer(buffer, buffer.size())?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}
