//! The worker pool: one worker per GPU slot, plus optional CPU-only slots.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::Notify;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

use super::scene_cache::SceneFileCache;
use super::worker::{Worker, WorkerShared};
use super::{HandlerRegistry, JobEventBus};
use crate::config::JobsConfig;
use crate::store::{BlobStore, Database};
use segsplat_gpu::context::select_adapters;
use segsplat_gpu::{AdapterFilter, AdapterReport, GpuContext};
use segsplat_vision::models::ModelsStatus;

/// One concurrent job runner; `gpu: None` is a CPU-only slot.
#[derive(Clone)]
pub struct WorkerSlot {
    pub gpu: Option<Arc<GpuContext>>,
}

pub struct WorkerPoolOptions {
    pub database: Database,
    pub blobs: Arc<dyn BlobStore>,
    /// Handed to every job (CLIP embeddings in `segment_then_splat`).
    pub models: Arc<ModelsStatus>,
    pub handlers: HandlerRegistry,
    pub bus: JobEventBus,
    pub jobs: JobsConfig,
    pub scratch_dir: PathBuf,
    /// Where workers keep local copies of scenes stored in an object store, and their budget.
    pub scene_cache_dir: PathBuf,
    pub scene_cache_bytes: u64,
    pub slots: Vec<WorkerSlot>,
    /// Woken when a job is queued in this process, so idle workers need not wait for a poll.
    pub job_queued: Arc<Notify>,
    /// Lease owner names are `{instance}/{slot}`.
    pub instance: String,
    pub shutdown_grace: Duration,
}

pub struct WorkerPool {
    shutdown: CancellationToken,
    tasks: Vec<JoinHandle<()>>,
    /// Each slot's GPU context once (slots of one adapter share it), handed back by
    /// [`WorkerPool::shutdown`] so the caller releases them last.
    gpus: Vec<Arc<GpuContext>>,
}

impl WorkerPool {
    pub fn start(options: WorkerPoolOptions) -> Self {
        let shutdown = CancellationToken::new();
        let shared = WorkerShared {
            database: options.database,
            blobs: options.blobs,
            models: options.models,
            handlers: options.handlers,
            bus: options.bus,
            jobs: options.jobs,
            job_queued: options.job_queued,
            shutdown: shutdown.clone(),
            scratch_dir: options.scratch_dir,
            scene_cache: Arc::new(SceneFileCache::new(
                options.scene_cache_dir,
                options.scene_cache_bytes,
            )),
            shutdown_grace: options.shutdown_grace,
        };
        metrics::gauge!("segsplat_worker_slots").set(options.slots.len() as f64);
        let mut gpus: Vec<Arc<GpuContext>> = Vec::new();
        for gpu in options.slots.iter().filter_map(|slot| slot.gpu.as_ref()) {
            if !gpus.iter().any(|known| Arc::ptr_eq(known, gpu)) {
                gpus.push(Arc::clone(gpu));
            }
        }
        let tasks = options
            .slots
            .into_iter()
            .enumerate()
            .map(|(index, slot)| {
                let device = slot
                    .gpu
                    .as_ref()
                    .map_or("cpu".to_string(), |gpu| gpu.report.name.clone());
                let worker = Worker {
                    shared: shared.clone(),
                    name: format!("{}/{index}", options.instance),
                    gpu: slot.gpu,
                };
                info!(worker = %worker.name, %device, "starting worker");
                tokio::spawn(worker.run())
            })
            .collect();
        Self {
            shutdown,
            tasks,
            gpus,
        }
    }

    pub fn slot_count(&self) -> usize {
        self.tasks.len()
    }

    /// Stops claiming, asks running handlers to stop, and waits until every running job is
    /// finished or handed back to the queue. Returns the workers' GPU contexts, for the caller
    /// to release ([`segsplat_gpu::release_context`]) after everything else on the GPU: a job
    /// stage that outlived its grace may still hold one, and must drop its buffers first.
    pub async fn shutdown(self) -> Vec<Arc<GpuContext>> {
        self.shutdown.cancel();
        for task in self.tasks {
            if let Err(error) = task.await {
                warn!(%error, "worker task ended abnormally");
            }
        }
        self.gpus
    }
}

/// GPUs for workers: every adapter the filter admits, with a device each. Blocking (adapter
/// enumeration and device creation); run it in `spawn_blocking`. Returns the opened contexts and,
/// for each adapter that could not be opened or when none was found, a reason.
pub fn open_adapters(filter: &AdapterFilter) -> (Vec<Arc<GpuContext>>, Vec<String>) {
    let mut contexts = Vec::new();
    let mut problems = Vec::new();
    let adapters = select_adapters(filter);
    if adapters.is_empty() {
        problems.push(format!(
            "no GPU adapter matches workers.adapters (name_contains={:?}, backends={:?}); \
             jobs stay queued",
            filter.name_contains, filter.backends
        ));
    }
    for (adapter, report) in adapters {
        log_adapter(&report);
        match GpuContext::from_adapter(&adapter) {
            Ok(mut context) => {
                // Timestamps for the jobs' gpu_busy_fraction; idle outside its short sample.
                if report.timestamp_queries
                    && let Err(error) = context.enable_kernel_profiling()
                {
                    warn!(adapter = %report.name, %error, "no kernel timing on this adapter");
                }
                contexts.push(Arc::new(context.with_kernel_choices(filter.kernels)))
            }
            Err(error) => {
                warn!(adapter = %report.name, %error, "cannot open GPU adapter");
                problems.push(format!("adapter {}: {error}", report.name));
            }
        }
    }
    (contexts, problems)
}

fn log_adapter(report: &AdapterReport) {
    info!(
        name = %report.name,
        backend = %report.backend,
        device_type = %report.device_type,
        driver = %report.driver,
        software = report.is_software,
        max_storage_buffer_binding_bytes = report.max_storage_buffer_binding_bytes,
        max_buffer_bytes = report.max_buffer_bytes,
        max_compute_workgroup_storage_bytes = report.max_compute_workgroup_storage_bytes,
        max_compute_invocations_per_workgroup = report.max_compute_invocations_per_workgroup,
        float32_atomics = report.float32_atomics,
        subgroups = report.subgroups,
        timestamp_queries = report.timestamp_queries,
        "GPU adapter"
    );
}
