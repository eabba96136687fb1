//! What a handler gets to run one job.

use std::path::PathBuf;
use std::sync::Arc;

use tokio_util::sync::CancellationToken;

use super::{JobFailure, ProgressReporter};
use crate::store::{BlobError, BlobStore, Database};
use segsplat_gpu::GpuContext;
use segsplat_vision::models::ModelsStatus;

/// How many generations of a named checkpoint a job keeps: the newest, and the one a resume
/// falls back to when the newest is torn.
pub const KEPT_CHECKPOINT_GENERATIONS: usize = 2;

/// How often a wait for the blob store looks for cancel and shutdown.
const STOP_POLL: std::time::Duration = std::time::Duration::from_millis(100);

/// Digits of a checkpoint generation in its key, zero-padded so keys sort by generation.
const GENERATION_DIGITS: usize = 12;

/// Blob key prefix under which job `job_id` keeps its checkpoints (deleted when it succeeds).
pub fn job_checkpoints_prefix(job_id: &str) -> String {
    format!("jobs/{job_id}/checkpoints/")
}

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

    /// Blob key of generation `generation` of a named checkpoint of this job; stable across
    /// attempts so a retry resumes.
    pub fn checkpoint_key(&self, name: &str, generation: u64) -> String {
        format!(
            "{}{generation:0width$}",
            self.checkpoint_generation_prefix(name),
            width = GENERATION_DIGITS
        )
    }

    /// A folder per checkpoint name: blob stores list by folder, not by any string prefix.
    /// `generations/` keeps it apart from the single key a checkpoint had before generations.
    fn checkpoint_generation_prefix(&self, name: &str) -> String {
        format!(
            "{}generations/{name}/",
            job_checkpoints_prefix(&self.job_id)
        )
    }

    /// The saved generations of a named checkpoint, oldest first, with their keys. A key saved
    /// before checkpoints had generations (`checkpoints/{name}`) counts as generation 0.
    fn checkpoint_generations(&self, name: &str) -> Result<Vec<(u64, String)>, BlobError> {
        let prefix = self.checkpoint_generation_prefix(name);
        let mut generations: Vec<(u64, String)> = self
            .blobs
            .list_prefix(&prefix)?
            .into_iter()
            .filter_map(|key| {
                let digits = key.strip_prefix(&prefix)?;
                let generation = digits.parse().ok()?;
                (digits.len() == GENERATION_DIGITS).then_some((generation, key))
            })
            .collect();
        let legacy = format!("{}{name}", job_checkpoints_prefix(&self.job_id));
        if self.blobs.exists(&legacy)? {
            generations.push((0, legacy));
        }
        generations.sort();
        Ok(generations)
    }
    /// Blob key prefix for this job's results.
    pub fn output_prefix(&self) -> String {
        job_output_prefix(&self.job_id)
    }

    /// Saves a checkpoint as the next generation (blocking I/O), notes it in the job's row (a
    /// lease that expires after a checkpoint is not counted as an attempt), then drops all but
    /// the newest [`KEPT_CHECKPOINT_GENERATIONS`].
    ///
    /// Why generations: a worker killed in the middle of an upload can leave a torn object on a
    /// store that does not reject short uploads (s3rver does not; S3 itself does), and a torn
    /// newest checkpoint must cost the steps since the one before, not the job.
    pub fn save_checkpoint(&self, name: &str, bytes: &[u8]) -> Result<(), BlobError> {
        let mut generations = self.checkpoint_generations(name)?;
        let next = generations
            .last()
            .map_or(1, |(generation, _)| generation + 1);
        let key = self.checkpoint_key(name, next);
        self.blobs.put_bytes(&key, bytes)?;
        self.progress.note_checkpoint();
        generations.push((next, key));
        let stale = generations
            .len()
            .saturating_sub(KEPT_CHECKPOINT_GENERATIONS);
        for (_, key) in &generations[..stale] {
            self.blobs.delete_prefix(key)?;
        }
        Ok(())
    }

    /// Runs a blob-store operation (blocking), and again while the store is unreachable, with
    /// backoff and a `warning` job event each time: for writes that must not be lost, such as a
    /// finished job's outputs. Stops waiting when the job is cancelled or the service stops.
    pub fn while_blobs_unavailable<T>(
        &self,
        what: &str,
        mut operation: impl FnMut() -> Result<T, BlobError>,
    ) -> Result<T, JobFailure> {
        let mut backoff = super::outage::Backoff::new();
        loop {
            let reason = match operation() {
                Err(error @ BlobError::Unavailable { .. }) => error.to_string(),
                other => return other.map_err(JobFailure::from),
            };
            let wait = backoff.next_wait();
            let message = format!("{reason}; trying {what} again in {} s", wait.as_secs_f64());
            tracing::warn!(job = %self.job_id, "{message}");
            self.progress.warn_detached("outage", &message);
            let deadline = std::time::Instant::now() + wait;
            while std::time::Instant::now() < deadline {
                self.stop_requested()?;
                std::thread::sleep(
                    STOP_POLL.min(deadline.saturating_duration_since(std::time::Instant::now())),
                );
            }
        }
    }

    /// The newest saved checkpoint of that name that `decode` accepts, if any (blocking I/O).
    /// A generation `decode` refuses (torn, corrupt, from an incompatible build) is skipped with
    /// a `warning` job event naming why, and the one before it is tried; when none is left the
    /// job starts over, which costs time but never the job.
    pub fn load_checkpoint<T>(
        &self,
        name: &str,
        decode: impl Fn(&[u8]) -> Result<T, String>,
    ) -> Result<Option<T>, BlobError> {
        for (generation, key) in self.checkpoint_generations(name)?.into_iter().rev() {
            let bytes = match self.blobs.get_bytes(&key) {
                Ok(bytes) => bytes,
                // Pruned by a writer between the listing and this read.
                Err(BlobError::NotFound { .. }) => continue,
                Err(error) => return Err(error),
            };
            match decode(&bytes) {
                Ok(value) => return Ok(Some(value)),
                Err(reason) => {
                    let message = format!(
                        "checkpoint `{name}` generation {generation} is unusable ({reason}); \
                         trying the one before it, else starting over"
                    );
                    tracing::warn!(job = %self.job_id, "{message}");
                    self.progress.warn_detached("resume", &message);
                }
            }
        }
        Ok(None)
    }
}
