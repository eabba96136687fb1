//! The intersection capacity follows the renders' peak: read now ([`Renderer::sync_capacity`],
//! for one-off renders), or without waiting ([`Renderer::request_capacity_check`] and
//! [`Renderer::apply_capacity_check`], for the training loop, which must not drain the queue
//! every few dozen steps to learn a number it can use a few steps late).

use segsplat_gpu::GpuContext;

use super::output::RenderError;
use super::renderer::Renderer;

/// What [`Renderer::sync_capacity`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CapacityReport {
    /// Largest intersection count of any render since the previous sync (unclamped).
    pub peak_intersections: u32,
    /// Capacity renders use from now on.
    pub capacity: u32,
    /// Some render since the previous sync needed more intersections than its buffers held, so
    /// it dropped tile entries (its image and gradients are approximate).
    pub overflowed: bool,
    /// How many renders since the previous read did.
    pub clamped_renders: u32,
}

/// Grow when the peak passes this fraction of the capacity.
const GROW_AT_FRACTION: f64 = 0.8;
/// New capacity = peak x this.
const GROWTH_FACTOR: f64 = 1.5;

/// The words of [`Renderer::peak_intersections`], which tile_budget.wgsl writes: the running
/// maximum of unclamped intersection counts since the host last cleared it, and the renders
/// clamped so far. The count is never cleared, so a read-back copy that is dropped for a newer
/// one (`DeferredRead` keeps only the newest) loses none of it.
pub(super) const PEAK_WORDS: u64 = 2;

struct PeakWords {
    peak: u32,
    clamped_so_far: u32,
}

impl PeakWords {
    fn parse(words: &[u32]) -> Self {
        Self {
            peak: words.first().copied().unwrap_or(0),
            clamped_so_far: words.get(1).copied().unwrap_or(0),
        }
    }
}

impl Renderer {
    /// Reads the peak intersection count of the renders since the last sync (one small
    /// read-back; waits for submitted work), grows the capacity when the peak nears it, and
    /// reports whether any of those renders overflowed. Their clamped renders count as used
    /// ([`Renderer::clamped_renders`]).
    pub fn sync_capacity(&mut self, ctx: &GpuContext) -> Result<CapacityReport, RenderError> {
        let report = self.sync_capacity_to_retry(ctx)?;
        self.clamped_renders += u64::from(report.clamped_renders);
        Ok(report)
    }

    /// [`Self::sync_capacity`] for a caller that renders again whatever overflowed, so its
    /// clamped renders are not counted as used.
    pub fn sync_capacity_to_retry(
        &mut self,
        ctx: &GpuContext,
    ) -> Result<CapacityReport, RenderError> {
        let words = PeakWords::parse(&ctx.read_vec::<u32>(&self.peak_intersections)?);
        ctx.queue
            .write_buffer(&self.peak_intersections, 0, bytemuck::bytes_of(&0u32));
        let used = self
            .smallest_capacity_used
            .take()
            .unwrap_or(self.intersection_capacity);
        let overflowed = words.peak > used;
        // Taken before growing, which fails for a peak past the adapter's limit: the caller
        // that renders again in smaller pieces then must not find these renders counted later.
        let clamped_renders = self.clamped_since_last_read(words.clamped_so_far);
        self.grow_for_peak(ctx, words.peak)?;
        Ok(CapacityReport {
            peak_intersections: words.peak,
            capacity: self.intersection_capacity,
            overflowed,
            clamped_renders,
        })
    }

    /// Records, with `encoder`, a copy of the peak for [`Self::apply_capacity_check`]; the
    /// caller submits `encoder` and then calls [`Self::capacity_check_submitted`] with what
    /// this returned. `None` when the previous two copies are still on their way (the peak
    /// keeps counting until the next request). The peak is not reset behind the copy: it runs
    /// on until the next blocking sync, so every copy holds the peaks of the copies before it
    /// and one that `DeferredRead` drops for a newer loses nothing (the capacity only grows,
    /// so an old peak read again changes nothing).
    pub fn request_capacity_check(&mut self, encoder: &mut segsplat_gpu::Encoder) -> Option<usize> {
        self.peak_read.record(encoder, &self.peak_intersections)
    }

    /// See [`Self::request_capacity_check`].
    pub fn capacity_check_submitted(&mut self, slot: usize) {
        self.peak_read.after_submit(slot);
    }

    /// Grows the capacity for the newest peak the device has delivered, without waiting (a
    /// peak not delivered yet is applied at a later call), and counts the clamped renders it
    /// reports as used. The training loop's renders clamp to their capacity, so one that
    /// overflowed in between dropped tile entries for a step: the cost of not draining the
    /// queue, the same as between two blocking syncs.
    pub fn apply_capacity_check(&mut self, ctx: &GpuContext) -> Result<(), RenderError> {
        let Some(bytes) = self.peak_read.take(ctx)? else {
            return Ok(());
        };
        let words = PeakWords::parse(&bytemuck::pod_collect_to_vec::<u8, u32>(&bytes));
        let clamped = self.clamped_since_last_read(words.clamped_so_far);
        self.clamped_renders += u64::from(clamped);
        self.grow_for_peak(ctx, words.peak)
    }

    /// The renders clamped since the newest count read so far, given a count just read; a
    /// copy older than that (a deferred one delivered after a sync) adds nothing.
    fn clamped_since_last_read(&mut self, clamped_so_far: u32) -> u32 {
        let new = clamped_so_far.saturating_sub(self.clamped_read);
        self.clamped_read = self.clamped_read.max(clamped_so_far);
        new
    }

    /// Grows the capacity to [`GROWTH_FACTOR`] x `peak` once `peak` passes
    /// [`GROW_AT_FRACTION`] of it; an error when `peak` exceeds what the adapter can hold.
    fn grow_for_peak(&mut self, ctx: &GpuContext, peak: u32) -> Result<(), RenderError> {
        let limit = Self::max_intersections(ctx);
        if peak as f64 > GROW_AT_FRACTION * self.intersection_capacity as f64 {
            let grown = (peak as f64 * GROWTH_FACTOR).ceil() as u64;
            if peak as u64 > limit {
                return Err(RenderError::IntersectionsExceedAdapter {
                    needed: peak as u64,
                    limit,
                });
            }
            self.set_intersection_capacity(grown.min(limit) as u32);
        }
        Ok(())
    }
}
