//! What the use cases share, built once when the service starts. REST handlers, gRPC methods
//! and the console hold one of these and call `usecases::*` with it, so a use case is written
//! once whatever the interface.

use std::sync::Arc;

use tokio::sync::Notify;

use segsplat_gpu::AdapterReport;
use segsplat_vision::language::SharedTextEncoder;

use crate::config::Config;
use crate::jobs::{HandlerRegistry, JobEventBus};
use crate::store::{BlobStore, Database};
use crate::usecases::serving::Serving;

#[derive(Clone)]
pub struct ServiceCore {
    pub config: Arc<Config>,
    pub database: Database,
    pub blobs: Arc<dyn BlobStore>,
    /// The job kinds this build runs.
    pub handlers: HandlerRegistry,
    /// Wakes event streams when a job changes.
    pub bus: JobEventBus,
    /// Wakes this process's idle workers when a job is queued.
    pub job_queued: Arc<Notify>,
    /// This process's GPU adapters; GPU jobs too large for all of them are refused when queued.
    pub adapters: Arc<[AdapterReport]>,
    /// The CLIP text encoder queries share (built on the first query).
    pub text_encoder: Arc<SharedTextEncoder>,
    /// Trained scenes on the GPU for masks, and exports.
    pub serving: Serving,
}
