//! Copies of several buffers taken in queue order and read by another thread.
//!
//! A training job's checkpoint needs the whole model and its optimiser state on the host. Read
//! with [`GpuContext::read_buffer`], the step loop's thread drains the queue and waits for the
//! bytes (issue 38, item 4). Here the loop only records copies into staging buffers and
//! submits them: the copies run after the steps before them and before the steps after, so they
//! hold the state of that moment. Whoever holds the [`PendingCopies`] (a writer thread) waits
//! for that one submission and maps the staging buffers, while the loop goes on submitting.
//! The staging buffers come back with the bytes ([`CopyStaging`]) for the next snapshot, so a
//! steady job allocates none after its first snapshots.
//!
//! The wait and the bytes are not counted in the context's [`crate::context::HostCosts`]: they
//! happen beside the step loop, whose figures those are.

use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::Duration;

use crate::{GpuContext, GpuError};

/// Staging room a reallocated buffer gets over what the copy needs, so a model that grows a
/// little between checkpoints does not reallocate every time.
const STAGING_GROWTH: f64 = 1.25;

/// How long a read waits for a map callback before polling the device again.
const CALLBACK_WAIT: Duration = Duration::from_millis(1);

/// Staging buffers (MAP_READ) kept between snapshots.
#[derive(Debug, Default)]
pub struct CopyStaging {
    buffers: Vec<wgpu::Buffer>,
}

impl CopyStaging {
    pub fn new() -> Self {
        Self::default()
    }

    /// Bytes of staging held.
    pub fn bytes(&self) -> u64 {
        self.buffers.iter().map(wgpu::Buffer::size).sum()
    }

    /// Records and submits copies of `sources` (each buffer's first `bytes`, a multiple of 4)
    /// into these staging buffers, growing the ones too small (counted as buffers created), and
    /// asks for them mapped. Returns at once: nothing here waits for the device.
    pub fn copy(
        mut self,
        ctx: &GpuContext,
        sources: &[(&wgpu::Buffer, u64)],
    ) -> Result<PendingCopies, GpuError> {
        // Mapping wants a non-empty range: an empty source still copies (and maps) one word.
        let lengths: Vec<u64> = sources
            .iter()
            .map(|(_, bytes)| bytes.max(&4).next_multiple_of(4))
            .collect();
        for ((source, _), &length) in sources.iter().zip(&lengths) {
            if length > source.size() {
                return Err(GpuError::Device(format!(
                    "a snapshot copy of {length} bytes from a buffer of {}",
                    source.size()
                )));
            }
        }
        self.buffers.truncate(sources.len());
        for (index, &length) in lengths.iter().enumerate() {
            let fits = self
                .buffers
                .get(index)
                .is_some_and(|buffer| buffer.size() >= length);
            if fits {
                continue;
            }
            let room = ((length as f64 * STAGING_GROWTH) as u64).next_multiple_of(4);
            let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("snapshot staging"),
                size: room.min(sources[index].0.size()).max(length),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            ctx.count_buffer_created();
            match self.buffers.get_mut(index) {
                Some(slot) => *slot = buffer,
                None => self.buffers.push(buffer),
            }
        }
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("snapshot copies"),
            });
        for (((source, _), staging), &length) in sources.iter().zip(&self.buffers).zip(&lengths) {
            encoder.copy_buffer_to_buffer(source, 0, staging, 0, length);
        }
        let submission = ctx.submit(encoder.finish());
        let (sender, mapped) = channel();
        for (index, (staging, &length)) in self.buffers.iter().zip(&lengths).enumerate() {
            let sender = sender.clone();
            staging.map_async(wgpu::MapMode::Read, 0..length, move |result| {
                // The receiver is gone only when the snapshot was dropped unread.
                let _ = sender.send((index, result));
            });
        }
        Ok(PendingCopies {
            staging: self,
            lengths,
            submission,
            mapped,
            device: ctx.device.clone(),
        })
    }
}

/// Copies submitted by [`CopyStaging::copy`], not yet read.
#[derive(Debug)]
pub struct PendingCopies {
    staging: CopyStaging,
    lengths: Vec<u64>,
    submission: wgpu::SubmissionIndex,
    mapped: Receiver<(usize, Result<(), wgpu::BufferAsyncError>)>,
    device: wgpu::Device,
}

impl PendingCopies {
    /// Bytes the copies hold.
    pub fn bytes(&self) -> u64 {
        self.lengths.iter().sum()
    }

    /// Waits for the copies' submission (not for work submitted after it) and returns each
    /// source's bytes, in the order given, with the staging buffers for the next snapshot.
    pub fn read(self) -> Result<(Vec<Vec<u8>>, CopyStaging), GpuError> {
        let Self {
            staging,
            lengths,
            submission,
            mapped,
            device,
        } = self;
        device.poll(wgpu::PollType::Wait {
            submission_index: Some(submission),
            timeout: None,
        })?;
        let mut done = vec![false; lengths.len()];
        while done.iter().any(|done| !done) {
            // The wait above ran this submission's callbacks, unless another thread's poll was
            // running them at that moment: then they arrive shortly.
            let (index, result) = match mapped.recv_timeout(CALLBACK_WAIT) {
                Ok(message) => message,
                Err(RecvTimeoutError::Timeout) => {
                    device.poll(wgpu::PollType::Poll)?;
                    continue;
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(GpuError::Device(
                        "a snapshot's map callback was dropped".to_string(),
                    ));
                }
            };
            result?;
            done[index] = true;
        }
        let mut bytes = Vec::with_capacity(lengths.len());
        for (buffer, &length) in staging.buffers.iter().zip(&lengths) {
            let copied = buffer
                .slice(0..length)
                .get_mapped_range()
                .map_err(|error| GpuError::Device(format!("reading a snapshot copy: {error}")))?
                .to_vec();
            bytes.push(copied);
        }
        for buffer in &staging.buffers {
            buffer.unmap();
        }
        Ok((bytes, staging))
    }
}
