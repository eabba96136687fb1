//! What every request handler shares.

use std::sync::Arc;

use metrics_exporter_prometheus::PrometheusHandle;
use serde::Serialize;
use tokio_util::sync::CancellationToken;

use segsplat_gpu::AdapterReport;
use segsplat_service::core::ServiceCore;

#[derive(Clone)]
pub struct AppState {
    /// What the use cases share; handlers parse, call one use case with it, and map the result.
    pub core: ServiceCore,
    pub workers: Arc<WorkerReadiness>,
    /// The ONNX models loaded at start (or why not); `/readyz` reports it.
    pub models: Arc<segsplat_vision::models::ModelsStatus>,
    pub metrics: PrometheusHandle,
    /// Cancelled when the service stops; long-lived responses (SSE) end then.
    pub shutdown: CancellationToken,
    /// `/readyz`'s checks, each run in the background at most once at a time.
    pub readiness: Arc<crate::readiness::ReadinessProbes>,
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
