//! Read-backs that do not wait for the device.
//!
//! A training loop reports its loss and checks its renders' intersection peak every few steps.
//! Reading them with [`GpuContext::read_buffer`] drains the queue each time: on a GPU the device
//! then idles while the host encodes the next step, and the staging buffer is a new allocation.
//! A [`DeferredRead`] instead copies the source into one of two staging buffers it keeps, maps it
//! when the device gets there, and hands back the newest finished copy whenever the host asks,
//! without blocking: the values are one request old (a few steps), which is what a progress
//! report or a capacity check can live with. Only the last read of a run waits
//! ([`DeferredRead::read_now`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

use crate::{GpuContext, GpuError};

const IDLE: u8 = 0;
const PENDING: u8 = 1;
const READY: u8 = 2;
const FAILED: u8 = 3;

#[derive(Debug)]
struct Slot {
    staging: wgpu::Buffer,
    state: Arc<AtomicU8>,
    /// The request this slot holds (higher is newer).
    request: u64,
}

/// Two staging buffers for one source buffer's first `size` bytes.
#[derive(Debug)]
pub struct DeferredRead {
    slots: [Slot; 2],
    size: u64,
    requests: u64,
}

impl DeferredRead {
    pub fn new(ctx: &GpuContext, label: &'static str, size: u64) -> Self {
        let size = size.max(4).next_multiple_of(4);
        let slot = || Slot {
            staging: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            state: Arc::new(AtomicU8::new(IDLE)),
            request: 0,
        };
        Self {
            slots: [slot(), slot()],
            size,
            requests: 0,
        }
    }

    /// Records a copy of `source` into a free staging buffer with `encoder` (the caller submits
    /// it) and returns the slot to [`Self::after_submit`]. `None` when both copies are still
    /// on their way: the request is skipped, the next one tries again.
    pub fn record(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::Buffer,
    ) -> Option<usize> {
        let free = self
            .slots
            .iter()
            .position(|slot| slot.state.load(Ordering::Acquire) == IDLE)
            .or_else(|| {
                // A finished copy nobody took yet is older than the one about to be made.
                let ready = self
                    .slots
                    .iter()
                    .enumerate()
                    .filter(|(_, slot)| slot.state.load(Ordering::Acquire) == READY)
                    .min_by_key(|(_, slot)| slot.request)
                    .map(|(index, _)| index)?;
                self.slots[ready].staging.unmap();
                self.slots[ready].state.store(IDLE, Ordering::Release);
                Some(ready)
            })?;
        encoder.copy_buffer_to_buffer(source, 0, &self.slots[free].staging, 0, self.size);
        Some(free)
    }

    /// Maps the slot [`Self::record`] gave once the submission holding its copy is done.
    pub fn after_submit(&mut self, slot: usize) {
        self.requests += 1;
        let target = &mut self.slots[slot];
        target.request = self.requests;
        target.state.store(PENDING, Ordering::Release);
        let state = Arc::clone(&target.state);
        target
            .staging
            .slice(..)
            .map_async(wgpu::MapMode::Read, move |result| {
                let done = if result.is_ok() { READY } else { FAILED };
                state.store(done, Ordering::Release);
            });
    }

    /// The newest finished copy's bytes, without waiting (`None` when none has finished since
    /// the last take). Older finished copies are dropped.
    pub fn take(&mut self, ctx: &GpuContext) -> Result<Option<Vec<u8>>, GpuError> {
        // Runs the map callbacks of whatever the device has finished; never waits.
        ctx.device
            .poll(wgpu::PollType::Poll)
            .map_err(|error| GpuError::Device(format!("polling the device: {error}")))?;
        self.take_ready(ctx)
    }

    /// Waits for every requested copy and returns the newest (`None` when nothing was asked).
    pub fn read_now(&mut self, ctx: &GpuContext) -> Result<Option<Vec<u8>>, GpuError> {
        ctx.wait_idle()?;
        self.take_ready(ctx)
    }

    fn take_ready(&mut self, ctx: &GpuContext) -> Result<Option<Vec<u8>>, GpuError> {
        if let Some(failed) = self
            .slots
            .iter()
            .find(|slot| slot.state.load(Ordering::Acquire) == FAILED)
        {
            failed.state.store(IDLE, Ordering::Release);
            return Err(GpuError::Device(
                "mapping a read-back buffer failed".to_string(),
            ));
        }
        let mut newest: Option<usize> = None;
        for (index, slot) in self.slots.iter().enumerate() {
            if slot.state.load(Ordering::Acquire) == READY
                && newest.is_none_or(|best| self.slots[best].request < slot.request)
            {
                newest = Some(index);
            }
        }
        let Some(newest) = newest else {
            return Ok(None);
        };
        let bytes = self.slots[newest]
            .staging
            .slice(..)
            .get_mapped_range()
            .map_err(|error| GpuError::Device(format!("reading a mapped buffer: {error}")))?
            .to_vec();
        for slot in &self.slots {
            if slot.state.load(Ordering::Acquire) == READY {
                slot.staging.unmap();
                slot.state.store(IDLE, Ordering::Release);
            }
        }
        ctx.count_read_back(self.size);
        Ok(Some(bytes))
    }
}
