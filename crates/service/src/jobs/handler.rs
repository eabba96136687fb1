//! The interface a job kind implements, and the registry that maps kinds to handlers.

use std::collections::BTreeMap;
use std::sync::Arc;

use futures::future::BoxFuture;

use super::JobContext;
use crate::store::BlobError;

/// Why a handler stopped without finishing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JobFailure {
    /// The handler saw [`JobContext::cancel`] at a step boundary.
    #[error("cancelled")]
    Cancelled,
    /// The handler saw [`JobContext::shutdown`]: the job goes back to the queue and resumes from
    /// its last checkpoint elsewhere or after restart.
    #[error("interrupted by shutdown")]
    Interrupted,
    /// Retrying cannot help (bad config for this scene, unsupported input).
    #[error("{0}")]
    Fatal(String),
    /// Might work on another attempt (device lost, out of memory, I/O hiccup).
    #[error("{0}")]
    Retryable(String),
    /// A dependency is down (the blob store cannot be reached): not the job's fault. The worker
    /// keeps the claim, waits with backoff and runs the handler again, which resumes from its
    /// last checkpoint; no attempt is spent.
    #[error("{0}")]
    Unavailable(String),
}

impl From<BlobError> for JobFailure {
    /// An unreachable store is [`JobFailure::Unavailable`]; any other blob error might pass on
    /// another attempt.
    fn from(error: BlobError) -> Self {
        match error {
            BlobError::Unavailable { .. } => JobFailure::Unavailable(error.to_string()),
            other => JobFailure::Retryable(other.to_string()),
        }
    }
}

/// One job kind (e.g. `reconstruct`, `segment_then_splat`). Handlers must be idempotent per step:
/// a job runs at least once and may resume from its last checkpoint after a crash.
pub trait JobHandler: Send + Sync {
    fn kind(&self) -> &'static str;

    /// Checks and normalises the config a client sent (defaults filled in); the error message is
    /// returned to the client as is, so it should name the field.
    fn validate_config(&self, config: &serde_json::Value) -> Result<serde_json::Value, String>;

    /// Whether the job needs a GPU; kinds that do not can also run on CPU-only worker slots.
    fn needs_gpu(&self) -> bool {
        true
    }

    /// Runs the job. Heavy work belongs in `spawn_blocking`; check `ctx.stop_requested()` at
    /// step boundaries.
    fn run(&self, ctx: JobContext) -> BoxFuture<'static, Result<(), JobFailure>>;
}

/// Handlers by kind.
#[derive(Clone, Default)]
pub struct HandlerRegistry {
    handlers: BTreeMap<&'static str, Arc<dyn JobHandler>>,
}

impl std::fmt::Debug for HandlerRegistry {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        formatter
            .debug_list()
            .entries(self.handlers.keys())
            .finish()
    }
}

impl HandlerRegistry {
    /// Adds (or replaces) the handler for its kind.
    pub fn register(&mut self, handler: Arc<dyn JobHandler>) {
        self.handlers.insert(handler.kind(), handler);
    }

    pub fn get(&self, kind: &str) -> Option<&Arc<dyn JobHandler>> {
        self.handlers.get(kind)
    }

    pub fn kinds(&self) -> Vec<&'static str> {
        self.handlers.keys().copied().collect()
    }

    /// The kinds a worker can run, given whether it has a GPU.
    pub fn kinds_for(&self, has_gpu: bool) -> Vec<&'static str> {
        self.handlers
            .values()
            .filter(|handler| has_gpu || !handler.needs_gpu())
            .map(|handler| handler.kind())
            .collect()
    }
}
