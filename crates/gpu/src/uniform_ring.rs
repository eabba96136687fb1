//! Kernel parameters without a buffer per dispatch.
//!
//! Every dispatch used to create its own small uniform buffer (`create_buffer_init`), so a step
//! allocated dozens of buffers and, since a new buffer means a new bind group, created dozens of
//! bind groups too. Parameters are now appended to one ring buffer on the CPU and written to the
//! GPU in one `write_buffer` when the context submits (wgpu applies it before that submission's
//! commands, and after the earlier submissions that read the old contents). Kernels bind the ring
//! with a dynamic offset, so their bind groups stay the same from step to step.
//!
//! A slot may be overwritten only once the commands that read it have been submitted: the
//! overwrite is a `write_buffer`, which wgpu applies before the *next* submission of any thread,
//! so a slot overwritten while its reader is still being recorded would be read with another
//! kernel's parameters. Which recording a push belongs to is not known here, so the ring keeps
//! the rule by thread: what a thread pushed stays protected until that thread submits
//! ([`RingPlacement`]). A push that would lap the oldest protected slot gets a buffer of its own
//! instead (counted in the context's host costs). One thread's recording is submitted by that
//! thread in this code base; a command buffer submitted by another thread is still safe, only
//! its thread's slots stay protected until it next submits or ends.
//!
//! Before stop 58 the rule was "no more than the ring's size pushed since the last submission",
//! counted across threads: a second thread's submissions reset the count, so with several
//! threads recording on one context (the GPU tests, a service whose training and mask renders
//! share a device) a slow recording could have its parameters overwritten. That is how the
//! NVIDIA H200 got wrong `deform_gpu` products at stop 54 (parallel tests on one context); a
//! ring small enough to lap in that binary makes the same failure on any adapter
//! (`tests/gpu_scan.rs`, `tests/deform_gpu.rs`).

use std::cell::RefCell;
use std::sync::{Arc, Mutex, Weak};
use std::thread::ThreadId;

/// Size of the ring: 4 MiB is thousands of dispatches' parameters.
pub const RING_BYTES: u64 = 4 << 20;

/// Where one push landed: bind the ring at this dynamic offset with this size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UniformSlot {
    pub offset: u32,
    pub size: u32,
}

/// Parameters pushed once and bound by several kernels (see `Binding::Uniform`): a slot of the
/// ring, or a buffer of their own when the ring was full.
#[derive(Debug, Clone)]
pub struct UniformParams {
    pub(crate) buffer: wgpu::Buffer,
    pub(crate) slot: Option<UniformSlot>,
}

/// Where pushes go in a ring of `capacity` bytes, and which slots are still protected: the
/// bookkeeping of [`UniformRing`] apart from the buffer, so it can be tested without a device.
/// Positions are absolute (laps times the capacity plus the offset), so "a whole lap after"
/// is a subtraction.
#[derive(Debug)]
pub struct RingPlacement {
    capacity: u64,
    alignment: u64,
    /// Absolute position of the next free byte.
    next: u64,
    /// For each thread that pushed since its last submission, the absolute position of its
    /// first such push: nothing at or after it may be overwritten yet.
    /// A few threads at most, in the order they opened: the first is the oldest.
    open: Vec<(ThreadId, u64)>,
}

/// Where [`RingPlacement::place`] put a push.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Placed {
    pub offset: u64,
    /// The push went back to the ring's start: what was pushed before must be written first,
    /// so each write stays contiguous.
    pub wrapped: bool,
    /// The thread had no slot protected before this push.
    pub opened: bool,
}

impl RingPlacement {
    pub fn new(capacity: u64, alignment: u64) -> Self {
        Self {
            capacity,
            alignment: alignment.max(4),
            next: 0,
            open: Vec::new(),
        }
    }

    /// Places `size` bytes pushed by `thread`, or `None` when they would overwrite a slot a
    /// thread has not submitted yet.
    pub fn place(&mut self, thread: ThreadId, size: u64) -> Option<Placed> {
        // The lap of the last byte pushed: a push that ended exactly at the ring's end leaves
        // the next one to wrap (and flush), not to start a lap unannounced.
        let lap_start = self.next.saturating_sub(1) / self.capacity * self.capacity;
        let aligned = (self.next - lap_start).next_multiple_of(self.alignment);
        let wrapped = aligned + size > self.capacity;
        let start = if wrapped {
            lap_start + self.capacity
        } else {
            lap_start + aligned
        };
        let end = start + size;
        // Entries are pushed as threads open them, at ever later positions.
        let oldest_protected = self.open.first().map_or(start, |&(_, first)| first);
        if end > oldest_protected + self.capacity {
            return None;
        }
        self.next = end;
        let opened = !self.open.iter().any(|&(known, _)| known == thread);
        if opened {
            self.open.push((thread, start));
        }
        Some(Placed {
            offset: start - (start / self.capacity) * self.capacity,
            wrapped,
            opened,
        })
    }

    /// `thread` submitted: what it pushed so far has been read or is queued to be.
    pub fn submitted(&mut self, thread: ThreadId) {
        self.open.retain(|&(known, _)| known != thread);
    }

    /// Threads whose pushes are protected (for tests and diagnostics).
    pub fn open_threads(&self) -> usize {
        self.open.len()
    }
}

/// What [`UniformRing::push`] did: where the bytes went, and whether the pushing thread's
/// slots became protected with them (so it should release them if it ends).
#[derive(Debug, Clone, Copy)]
pub struct Pushed {
    pub slot: UniformSlot,
    pub opened: bool,
}

/// This thread's id, looked up once: every kernel's parameters are pushed under it.
pub(crate) fn this_thread() -> ThreadId {
    thread_local! {
        static ID: ThreadId = std::thread::current().id();
    }
    ID.with(|id| *id)
}

#[derive(Debug)]
pub struct UniformRing {
    buffer: wgpu::Buffer,
    placement: RingPlacement,
    /// Bytes pushed since the last flush, to be written at `pending_start`.
    pending: Vec<u8>,
    pending_start: u64,
}

impl UniformRing {
    pub fn new(device: &wgpu::Device, limits: &wgpu::Limits) -> Self {
        Self::with_capacity(device, limits, RING_BYTES)
    }

    /// A ring of `capacity` bytes: tests use a small one to lap it quickly.
    pub fn with_capacity(device: &wgpu::Device, limits: &wgpu::Limits, capacity: u64) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("uniform ring"),
                size: capacity,
                usage: wgpu::BufferUsages::UNIFORM
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            placement: RingPlacement::new(
                capacity,
                u64::from(limits.min_uniform_buffer_offset_alignment),
            ),
            pending: Vec::new(),
            pending_start: 0,
        }
    }

    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Appends `bytes` (at most 64 KiB, one uniform binding) pushed by `thread`; `None` when
    /// the ring cannot take them without overwriting a slot whose reader is not submitted yet,
    /// and the caller should make a buffer of its own.
    pub fn push(&mut self, queue: &wgpu::Queue, thread: ThreadId, bytes: &[u8]) -> Option<Pushed> {
        // Uniform bindings are sized in multiples of 16 bytes.
        let size = (bytes.len() as u64).max(16).next_multiple_of(16);
        let placed = self.placement.place(thread, size)?;
        if placed.wrapped || placed.offset < self.pending_start {
            self.flush(queue);
        }
        if self.pending.is_empty() {
            self.pending_start = placed.offset;
        }
        // Alignment padding between pushes is written too (zeros), keeping one write per flush.
        self.pending
            .resize((placed.offset - self.pending_start) as usize, 0);
        self.pending.extend_from_slice(bytes);
        self.pending
            .resize((placed.offset + size - self.pending_start) as usize, 0);
        Some(Pushed {
            slot: UniformSlot {
                offset: placed.offset as u32,
                size: size as u32,
            },
            opened: placed.opened,
        })
    }

    /// Writes what was pushed since the last flush.
    pub fn flush(&mut self, queue: &wgpu::Queue) {
        if !self.pending.is_empty() {
            queue.write_buffer(&self.buffer, self.pending_start, &self.pending);
            self.pending.clear();
        }
    }

    /// Flushes and notes that `thread` submits next: the context calls this before every
    /// submission.
    pub fn before_submit(&mut self, queue: &wgpu::Queue, thread: ThreadId) {
        self.flush(queue);
        self.placement.submitted(thread);
    }

    /// `thread` ended: whatever it recorded and did not submit will never run.
    pub fn thread_ended(&mut self, thread: ThreadId) {
        self.placement.submitted(thread);
    }

    pub fn open_threads(&self) -> usize {
        self.placement.open_threads()
    }
}

/// Rings that hold slots for this thread, released when it ends: a thread that recorded,
/// failed before submitting and then exited (a blocking task's thread) would otherwise keep its
/// slots protected for the ring's lifetime, and every later push would need a buffer of its
/// own.
struct ThreadRings {
    thread: ThreadId,
    rings: Vec<Weak<Mutex<UniformRing>>>,
}

impl Drop for ThreadRings {
    fn drop(&mut self) {
        for ring in self.rings.drain(..).filter_map(|ring| ring.upgrade()) {
            ring.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .thread_ended(self.thread);
        }
    }
}

thread_local! {
    static THREAD_RINGS: RefCell<Option<ThreadRings>> = const { RefCell::new(None) };
}

/// Notes that this thread pushed into `ring`, so its slots are released if it ends without
/// submitting again.
pub(crate) fn release_when_thread_ends(ring: &Arc<Mutex<UniformRing>>) {
    // During the thread's own teardown there is nothing left to register into.
    let _ = THREAD_RINGS.try_with(|cell| {
        let mut cell = cell.borrow_mut();
        let registry = cell.get_or_insert_with(|| ThreadRings {
            thread: this_thread(),
            rings: Vec::new(),
        });
        if registry
            .rings
            .iter()
            .any(|known| std::ptr::eq(known.as_ptr(), Arc::as_ptr(ring)))
        {
            return;
        }
        registry.rings.retain(|known| known.strong_count() > 0);
        registry.rings.push(Arc::downgrade(ring));
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A push back at the ring's start by a thread with nothing protected.
    const WRAPPED_TO_START: Option<Placed> = Some(Placed {
        offset: 0,
        wrapped: true,
        opened: true,
    });

    fn other_thread() -> ThreadId {
        std::thread::spawn(|| std::thread::current().id())
            .join()
            .expect("thread")
    }

    #[test]
    fn pushes_are_aligned_and_wrap_at_the_end() {
        let me = std::thread::current().id();
        let mut ring = RingPlacement::new(1024, 256);
        let offsets: Vec<_> = (0..4)
            .map(|_| ring.place(me, 80).expect("room").offset)
            .collect();
        assert_eq!(offsets, [0, 256, 512, 768]);
        // A lap on one thread that has not submitted would overwrite its own first slot.
        assert_eq!(ring.place(me, 80), None);
        ring.submitted(me);
        assert_eq!(ring.place(me, 80), WRAPPED_TO_START);
    }

    #[test]
    fn a_push_after_one_that_ended_at_the_ring_end_wraps() {
        let me = std::thread::current().id();
        let mut ring = RingPlacement::new(1024, 256);
        assert_eq!(ring.place(me, 768).map(|p| p.offset), Some(0));
        assert_eq!(ring.place(me, 256).map(|p| p.offset), Some(768));
        ring.submitted(me);
        assert_eq!(ring.place(me, 64), WRAPPED_TO_START);
    }

    #[test]
    fn another_threads_submission_does_not_free_a_recording_slot() {
        let recording = std::thread::current().id();
        let busy = other_thread();
        let mut ring = RingPlacement::new(1024, 256);
        assert_eq!(ring.place(recording, 64).map(|p| p.offset), Some(0));
        // The other thread pushes and submits over and over: it may fill the rest of the lap,
        // but never the slot the recording thread has not submitted.
        let mut taken = Vec::new();
        for _ in 0..8 {
            if let Some(placed) = ring.place(busy, 64) {
                taken.push(placed.offset);
            }
            ring.submitted(busy);
        }
        assert_eq!(taken, [256, 512, 768]);
        assert_eq!(ring.open_threads(), 1);
        ring.submitted(recording);
        assert_eq!(ring.place(busy, 64).map(|p| p.offset), Some(0));
    }

    #[test]
    fn a_push_that_cannot_fit_is_refused_without_moving_the_cursor() {
        let me = std::thread::current().id();
        let mut ring = RingPlacement::new(1024, 16);
        assert_eq!(ring.place(me, 1000).map(|p| p.offset), Some(0));
        assert_eq!(ring.place(me, 64), None);
        ring.submitted(me);
        assert_eq!(ring.place(me, 64), WRAPPED_TO_START);
    }
}
