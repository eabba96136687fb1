//! Running queued jobs: the handler interface job kinds implement, the context a handler gets
//! (scene files, GPU, progress, cancellation, checkpoints), and the worker pool that leases jobs
//! from the database queue (`store::jobs`) and runs them.

mod context;
mod events;
mod handler;
mod handler_run;
mod identity;
mod lease_reaper;
mod outage;
mod pool;
mod progress;
mod remote_wakeups;
mod scene_cache;
mod temp_sweep;
mod worker;

pub use context::{JobContext, job_checkpoints_prefix, job_output_prefix};
pub use events::JobEventBus;
pub use handler::{HandlerRegistry, JobFailure, JobHandler};
pub use identity::{ProcessIdentity, host_name};
pub use lease_reaper::LeaseReaper;
pub use pool::{WorkerPool, WorkerPoolOptions, WorkerSlot, open_adapters};
pub use progress::{Progress, ProgressReporter};
pub use remote_wakeups::forward_remote_wakeups;
pub use temp_sweep::{SweepPlaces, sweep_leftovers};

#[derive(Debug, thiserror::Error)]
pub enum JobsError {
    #[error(transparent)]
    Store(#[from] crate::store::StoreError),
    #[error(transparent)]
    Blob(#[from] crate::store::BlobError),
}
