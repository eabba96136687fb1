//! Checkpoints encoded and stored by a thread of their own, so the step loop pays only for the
//! read-back of the model (the snapshot) and goes on training while the object store takes the
//! bytes (issue 38, item 4). One write at a time: a snapshot handed over while the previous one
//! is still being written waits for it, so at most two checkpoints are in memory.

use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::{Scope, ScopedJoinHandle};

use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::train::TrainerMeta;

use crate::jobs::{JobContext, JobFailure};
use crate::store::BlobError;

/// A checkpoint and the step it was taken at; boxed, as the channel moves it whole.
type Snapshot = (u32, Box<Checkpoint<TrainerMeta>>);

/// What the writer did, read when the stage ends.
#[derive(Debug, Default)]
struct Outcome {
    /// The first write that failed for a reason other than the store being unavailable: the
    /// stage fails with it at the next checkpoint or at its end.
    failure: Option<JobFailure>,
    /// Seconds spent encoding and storing, off the step loop.
    seconds: f64,
}

pub struct CheckpointWriter<'scope> {
    sender: Option<SyncSender<Snapshot>>,
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
        let outcome = Arc::new(Mutex::new(Outcome::default()));
        let shared = Arc::clone(&outcome);
        // Progress notes spawn onto the job's runtime, which a plain thread has not entered.
        let runtime = tokio::runtime::Handle::try_current().ok();
        let thread = scope.spawn(move || {
            let _entered = runtime.as_ref().map(tokio::runtime::Handle::enter);
            write_all(ctx, name, &receiver, &shared);
        });
        Self {
            sender: Some(sender),
            outcome,
            thread: Some(thread),
        }
    }

    /// Hands `checkpoint` (taken at `step`) to the writer, after the previous one is written;
    /// fails with an earlier write's failure.
    pub fn write(
        &mut self,
        step: u32,
        checkpoint: Checkpoint<TrainerMeta>,
    ) -> Result<(), JobFailure> {
        self.take_failure()?;
        let sent = self
            .sender
            .as_ref()
            .map(|sender| sender.send((step, Box::new(checkpoint))));
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
    outcome: &Mutex<Outcome>,
) {
    for (step, checkpoint) in receiver {
        let started = std::time::Instant::now();
        let written = store(ctx, name, step, &checkpoint);
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
