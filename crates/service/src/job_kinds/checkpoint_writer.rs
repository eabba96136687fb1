//! Checkpoints read back, encoded and stored by a thread of their own (issue 38, item 4). The
//! step loop only records GPU copies of the trainer's state ([`Trainer::checkpoint_snapshot`])
//! and hands them over; this thread waits for those copies, builds the checkpoint and stores it
//! while training goes on. One write at a time: a snapshot handed over while the previous one is
//! still being written waits for it, so at most two snapshots (and two sets of staging buffers,
//! handed back here for reuse) exist.

use std::sync::mpsc::{Receiver, Sender, SyncSender, channel, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::{Scope, ScopedJoinHandle};

use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::train::{PendingCheckpoint, Trainer, TrainerMeta};
use segsplat_gpu::snapshot_copies::CopyStaging;

use crate::jobs::{JobContext, JobFailure};
use crate::store::BlobError;

/// A snapshot on its way from the GPU; boxed, as the channel moves it whole.
type Snapshot = Box<PendingCheckpoint>;

/// What the writer did, read when the stage ends.
#[derive(Debug, Default)]
struct Outcome {
    /// The first write that failed for a reason other than the store being unavailable: the
    /// stage fails with it at the next checkpoint or at its end.
    failure: Option<JobFailure>,
    /// Seconds spent waiting for the snapshots' copies, encoding and storing, off the step
    /// loop.
    seconds: f64,
}

pub struct CheckpointWriter<'scope> {
    sender: Option<SyncSender<Snapshot>>,
    /// Staging buffers of written snapshots, for the next ones.
    staging: Receiver<CopyStaging>,
    outcome: Arc<Mutex<Outcome>>,
    thread: Option<ScopedJoinHandle<'scope, ()>>,
}

impl<'scope> CheckpointWriter<'scope> {
    /// Starts the writer in `scope`; it stores every snapshot it is given under `name`.
    pub fn start<'env>(
        scope: &'scope Scope<'scope, 'env>,
        ctx: &'env JobContext,
        name: &'env str,
    ) -> Self {
        // A rendezvous channel: a hand-over waits until the writer is free.
        let (sender, receiver) = sync_channel(0);
        let (staging_back, staging) = channel();
        let outcome = Arc::new(Mutex::new(Outcome::default()));
        let shared = Arc::clone(&outcome);
        // Progress notes spawn onto the job's runtime, which a plain thread has not entered.
        let runtime = tokio::runtime::Handle::try_current().ok();
        let thread = scope.spawn(move || {
            let _entered = runtime.as_ref().map(tokio::runtime::Handle::enter);
            write_all(ctx, name, &receiver, &staging_back, &shared);
        });
        Self {
            sender: Some(sender),
            staging,
            outcome,
            thread: Some(thread),
        }
    }

    /// Takes `trainer`'s snapshot (GPU copies, no read-back here) into staging buffers an
    /// earlier snapshot used, when one is free, and hands it to the writer once the previous
    /// one is written; fails with an earlier write's failure.
    pub fn write(&mut self, trainer: &Trainer) -> Result<(), JobFailure> {
        self.take_failure()?;
        let staging = self.staging.try_recv().unwrap_or_default();
        let snapshot = trainer
            .checkpoint_snapshot(staging)
            .map_err(super::training::train_failure)?;
        let sent = self
            .sender
            .as_ref()
            .map(|sender| sender.send(Box::new(snapshot)));
        match sent {
            Some(Ok(())) => Ok(()),
            // The writer ended early: only a panic does that.
            _ => Err(JobFailure::Retryable(
                "the checkpoint writer stopped".to_string(),
            )),
        }
    }

    /// Waits for the last write; returns the seconds spent writing, or the first failure.
    pub fn finish(mut self) -> Result<f64, JobFailure> {
        self.sender = None;
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            return Err(JobFailure::Retryable(
                "the checkpoint writer panicked".to_string(),
            ));
        }
        self.take_failure()?;
        Ok(lock(&self.outcome).seconds)
    }

    fn take_failure(&self) -> Result<(), JobFailure> {
        match lock(&self.outcome).failure.take() {
            Some(failure) => Err(failure),
            None => Ok(()),
        }
    }
}

fn lock(outcome: &Mutex<Outcome>) -> std::sync::MutexGuard<'_, Outcome> {
    outcome
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn write_all(
    ctx: &JobContext,
    name: &str,
    receiver: &Receiver<Snapshot>,
    staging_back: &Sender<CopyStaging>,
    outcome: &Mutex<Outcome>,
) {
    for snapshot in receiver {
        let started = std::time::Instant::now();
        let step = snapshot.step();
        let written = snapshot
            .finish()
            .map_err(|error| {
                JobFailure::Retryable(format!("reading the checkpoint at step {step}: {error}"))
            })
            .and_then(|(checkpoint, staging)| {
                // The step loop may be gone already: the buffers are then simply dropped.
                let _ = staging_back.send(staging);
                store(ctx, name, step, &checkpoint)
            });
        let mut outcome = lock(outcome);
        outcome.seconds += started.elapsed().as_secs_f64();
        if let Err(failure) = written {
            outcome.failure.get_or_insert(failure);
        }
    }
}

/// Encodes and stores one checkpoint. An unavailable store skips it (training goes on and the
/// next checkpoint tries again), as a dependency's outage is not the job's fault.
fn store(
    ctx: &JobContext,
    name: &str,
    step: u32,
    checkpoint: &Checkpoint<TrainerMeta>,
) -> Result<(), JobFailure> {
    let bytes = checkpoint
        .to_bytes()
        .map_err(|error| JobFailure::Retryable(format!("encoding the checkpoint: {error}")))?;
    match ctx.save_checkpoint(name, &bytes) {
        Err(error @ BlobError::Unavailable { .. }) => {
            let message = format!("{error}; checkpoint at step {step} skipped, training goes on");
            tracing::warn!(job = %ctx.job_id, "{message}");
            ctx.progress.warn_detached("train", &message);
            Ok(())
        }
        other => other.map_err(JobFailure::from),
    }
}
