//! Kernel parameters without a buffer per dispatch.
//!
//! Every dispatch used to create its own small uniform buffer (`create_buffer_init`), so a step
//! allocated dozens of buffers and, since a new buffer means a new bind group, created dozens of
//! bind groups too. Parameters are now appended to one ring buffer on the CPU and written to the
//! GPU in one `write_buffer` when the context submits (wgpu applies it before that submission's
//! commands, and after the earlier submissions that read the old contents). Kernels bind the ring
//! with a dynamic offset, so their bind groups stay the same from step to step.
//!
//! A slot is overwritten only after the cursor has gone once round the ring, `RING_BYTES` later:
//! a command buffer recorded with ring parameters must be submitted before that many more bytes
//! of parameters are pushed (a few hundred steps of training). Pushes that would lap the ring
//! before any submission get a buffer of their own instead (counted in the context's host costs).

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

#[derive(Debug)]
pub struct UniformRing {
    buffer: wgpu::Buffer,
    alignment: u64,
    /// Next free byte.
    cursor: u64,
    /// Bytes pushed since the last flush, to be written at `pending_start`.
    pending: Vec<u8>,
    pending_start: u64,
    /// Bytes pushed since the last submission, which must stay under the ring's size.
    since_submit: u64,
}

impl UniformRing {
    pub fn new(device: &wgpu::Device, limits: &wgpu::Limits) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("uniform ring"),
                size: RING_BYTES,
                usage: wgpu::BufferUsages::UNIFORM
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            alignment: u64::from(limits.min_uniform_buffer_offset_alignment.max(4)),
            cursor: 0,
            pending: Vec::new(),
            pending_start: 0,
            since_submit: 0,
        }
    }

    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Appends `bytes` (at most 64 KiB, one uniform binding); `None` when the ring cannot take them
    /// before the next submission, and the caller should make a buffer of its own.
    pub fn push(&mut self, queue: &wgpu::Queue, bytes: &[u8]) -> Option<UniformSlot> {
        // Uniform bindings are sized in multiples of 16 bytes.
        let size = (bytes.len() as u64).max(16).next_multiple_of(16);
        let mut offset = self.cursor.next_multiple_of(self.alignment);
        if self.since_submit + size + self.alignment > RING_BYTES {
            return None;
        }
        if offset + size > RING_BYTES {
            // Wrap: what is pending goes out first, in its own write, so each write is contiguous.
            self.flush(queue);
            offset = 0;
            self.pending_start = 0;
        }
        if self.pending.is_empty() {
            self.pending_start = offset;
        }
        // Alignment padding between pushes is written too (zeros), keeping one write per flush.
        self.pending
            .resize((offset - self.pending_start) as usize, 0);
        self.pending.extend_from_slice(bytes);
        self.pending
            .resize((offset + size - self.pending_start) as usize, 0);
        self.since_submit += size + self.alignment;
        self.cursor = offset + size;
        Some(UniformSlot {
            offset: offset as u32,
            size: size as u32,
        })
    }

    /// Writes what was pushed since the last flush; the context calls this before every
    /// submission.
    pub fn flush(&mut self, queue: &wgpu::Queue) {
        if !self.pending.is_empty() {
            queue.write_buffer(&self.buffer, self.pending_start, &self.pending);
            self.pending.clear();
        }
    }

    /// Flushes and notes that a submission follows.
    pub fn before_submit(&mut self, queue: &wgpu::Queue) {
        self.flush(queue);
        self.since_submit = 0;
    }
}
