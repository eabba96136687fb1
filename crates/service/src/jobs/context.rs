//! What a handler gets to run one job.

use std::path::PathBuf;
use std::sync::Arc;

use tokio_util::sync::CancellationToken;

use super::{JobFailure, ProgressReporter};
use crate::store::{BlobError, BlobStore, Database};
use segsplat_gpu::GpuContext;
use segsplat_vision::models::ModelsStatus;

/// Blob key prefix under which job `job_id` stores its results.
pub fn job_output_prefix(job_id: &str) -> String {
    format!("jobs/{job_id}/output")
}

pub struct JobContext {
    pub job_id: String,
    pub scene_id: String,
    pub kind: String,
    /// 1 for the first claim; higher when resuming after a crash or a lost lease.
    pub attempt: u32,
    /// The uploaded scene's files (read-only).
    pub scene_dir: PathBuf,
    /// Scratch space for this attempt, removed afterwards.
    pub work_dir: PathBuf,
    /// The config as the handler's `validate_config` returned it.
    pub config: serde_json::Value,
    /// The worker's GPU; `None` on CPU-only slots (only for kinds with `needs_gpu() == false`).
    pub gpu: Option<Arc<GpuContext>>,
    pub blobs: Arc<dyn BlobStore>,
    /// The ONNX models the service loaded (CLIP for object embeddings), or why there are none.
    pub models: Arc<ModelsStatus>,
    /// For job kinds that record results in tables (objects and their embeddings).
    pub database: Database,
    pub progress: ProgressReporter,
    /// Cancelled when the user cancels the job or this worker lost its lease.
    pub cancel: CancellationToken,
    /// Cancelled when the service shuts down: stop and return [`JobFailure::Interrupted`].
    pub shutdown: CancellationToken,
}

impl JobContext {
    /// `Err` when the handler should stop at this step boundary.
    pub fn stop_requested(&self) -> Result<(), JobFailure> {
        if self.cancel.is_cancelled() {
            Err(JobFailure::Cancelled)
        } else if self.shutdown.is_cancelled() {
            Err(JobFailure::Interrupted)
        } else {
            Ok(())
        }
    }

    /// Blob key of a named checkpoint of this job; stable across attempts so a retry resumes.
    pub fn checkpoint_key(&self, name: &str) -> String {
        format!("jobs/{}/checkpoints/{name}", self.job_id)
    }

    /// Blob key prefix for this job's results.
    pub fn output_prefix(&self) -> String {
        job_output_prefix(&self.job_id)
    }

    /// Saves a checkpoint atomically (blocking I/O), and notes it in the job's row (a lease
    /// that expires after a checkpoint is not counted as an attempt).
    pub fn save_checkpoint(&self, name: &str, bytes: &[u8]) -> Result<(), BlobError> {
        self.blobs.put_bytes(&self.checkpoint_key(name), bytes)?;
        self.progress.note_checkpoint();
        Ok(())
    }

    /// The last saved checkpoint of that name, if any (blocking I/O).
    pub fn load_checkpoint(&self, name: &str) -> Result<Option<Vec<u8>>, BlobError> {
        match self.blobs.get_bytes(&self.checkpoint_key(name)) {
            Ok(bytes) => Ok(Some(bytes)),
            Err(BlobError::NotFound { .. }) => Ok(None),
            Err(error) => Err(error),
        }
    }
}
