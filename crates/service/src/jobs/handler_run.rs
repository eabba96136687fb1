//! One run of a job's handler inside a claim: the scene's files found (in place, or fetched
//! into the worker's scene cache), the context built, the handler run. A claim runs it again
//! after an outage of the blob store (`jobs::outage`).

use std::path::PathBuf;
use std::sync::Arc;

use tokio_util::sync::CancellationToken;

use super::scene_cache::CachedScene;
use super::worker::WorkerShared;
use super::{JobContext, JobFailure, JobHandler, ProgressReporter};
use crate::store::jobs::JobRecord;
use segsplat_gpu::GpuContext;

/// What one run of a job's handler needs; a claim runs it again after an outage of the blob
/// store ([`run_through_outages`]).
pub(crate) struct HandlerRun {
    pub shared: WorkerShared,
    pub job: JobRecord,
    pub handler: Arc<dyn JobHandler>,
    pub gpu: Option<Arc<GpuContext>>,
    pub lease_owner: String,
    pub work_dir: PathBuf,
    pub cancel: CancellationToken,
    pub shutdown: CancellationToken,
}

impl HandlerRun {
    pub fn progress(&self) -> ProgressReporter {
        ProgressReporter::new(
            self.shared.database.clone(),
            self.shared.bus.clone(),
            self.job.id.clone(),
            self.lease_owner.clone(),
        )
    }

    /// Finds the scene's files and runs the handler once.
    pub async fn once(&self) -> Result<(), JobFailure> {
        // Held to the end of the run, so the scene's local copy stays.
        let (scene_dir, _scene_copy) = self.prepare_dirs().await?;
        let job = &self.job;
        let context = JobContext {
            job_id: job.id.clone(),
            scene_id: job.scene_id.clone(),
            kind: job.kind.clone(),
            attempt: job.attempts,
            scene_dir,
            work_dir: self.work_dir.clone(),
            config: job.config.clone(),
            gpu: self.gpu.clone(),
            blobs: self.shared.blobs.clone(),
            models: self.shared.models.clone(),
            database: self.shared.database.clone(),
            progress: self.progress(),
            cancel: self.cancel.clone(),
            shutdown: self.shutdown.clone(),
        };
        self.handler.run(context).await
    }

    /// Creates the scratch folder and finds the scene's files: in place in a local blob store,
    /// else in this host's scene cache (fetched on first use).
    async fn prepare_dirs(&self) -> Result<(PathBuf, Option<CachedScene>), JobFailure> {
        let blobs = self.shared.blobs.clone();
        let cache = self.shared.scene_cache.clone();
        let scene_id = self.job.scene_id.clone();
        let work_dir = self.work_dir.clone();
        tokio::task::spawn_blocking(move || {
            std::fs::create_dir_all(&work_dir).map_err(|error| {
                JobFailure::Retryable(format!("cannot create {}: {error}", work_dir.display()))
            })?;
            if let Some(local) = blobs.local_path(&format!("scenes/{scene_id}/files"))
                && local.is_dir()
            {
                return Ok((local, None));
            }
            let copy = cache.checkout(blobs.as_ref(), &scene_id)?;
            Ok((copy.dir.clone(), Some(copy)))
        })
        .await
        .map_err(|error| {
            JobFailure::Retryable(format!("preparing the job's folders crashed: {error}"))
        })?
    }
}
