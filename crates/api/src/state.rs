//! What every request handler shares.

use std::sync::Arc;

use metrics_exporter_prometheus::PrometheusHandle;
use serde::Serialize;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;

use segsplat_gpu::AdapterReport;
use segsplat_service::config::Config;
use segsplat_service::jobs::{HandlerRegistry, JobEventBus};
use segsplat_service::store::{BlobStore, Database};

#[derive(Clone)]
pub struct AppState {
    pub config: Arc<Config>,
    pub database: Database,
    pub blobs: Arc<dyn BlobStore>,
    pub handlers: HandlerRegistry,
    pub bus: JobEventBus,
    /// Wakes this process's idle workers when a job is queued.
    pub job_queued: Arc<Notify>,
    pub workers: Arc<WorkerReadiness>,
    /// The ONNX models loaded at start (or why not); `/readyz` reports it.
    pub models: Arc<segsplat_vision::models::ModelsStatus>,
    /// The CLIP text encoder queries share (built on the first query).
    pub text_encoder: Arc<segsplat_vision::language::SharedTextEncoder>,
    /// Trained scenes on the GPU for masks, and exports.
    pub serving: segsplat_service::usecases::serving::Serving,
    pub metrics: PrometheusHandle,
    /// Cancelled when the service stops; long-lived responses (SSE) end then.
    pub shutdown: CancellationToken,
}

/// What `/readyz` reports about GPU workers, fixed at start.
#[derive(Debug, Clone, Serialize)]
pub struct WorkerReadiness {
    /// Workers run in this process at all.
    pub enabled: bool,
    pub gpu_slots: usize,
    pub cpu_slots: usize,
    pub adapters: Vec<AdapterReport>,
    /// Why there are no GPU workers, when there are none.
    pub problems: Vec<String>,
}
