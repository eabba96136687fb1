//! How full a stretch of work kept the GPU, from the begin and end timestamps of its passes.
//!
//! A step's passes run one after another on the queue. Where the host recorded and submitted the
//! next step before the GPU finished the last, the passes follow each other with no time between
//! them; where the host fell behind, the GPU's timeline has a gap. So the share of the timeline,
//! from the first pass's begin to the last pass's end, that passes fill is how busy the host
//! kept the GPU, in the GPU's own clock: the host's latency before the first pass (a wall-clock
//! measure from an idle device counts it) is left out, and the barriers and launches between
//! the dispatches of one pass count as busy (they are the GPU's own cost of the work). Copies and
//! clears recorded between passes are not timed, so they count as gaps: a few microseconds a
//! step.

/// The GPU's timeline over the timed passes.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct PassTimeline {
    /// Passes timed.
    pub passes: u32,
    /// Passes recorded after the profiler was full (not on the timeline).
    pub untimed_passes: u32,
    /// Milliseconds inside at least one pass.
    pub busy_ms: f64,
    /// Milliseconds from the first pass's begin to the last pass's end.
    pub span_ms: f64,
    /// The longest stretch with no pass running, in milliseconds.
    pub longest_gap_ms: f64,
}

impl PassTimeline {
    /// From a begin and an end tick per pass (in any order; passes may overlap where the GPU
    /// ran two at once) and the length of a tick.
    pub fn from_ticks(ticks: &[u64], ns_per_tick: f64, untimed_passes: u32) -> Self {
        let mut intervals: Vec<(u64, u64)> = ticks
            .chunks_exact(2)
            .map(|pair| (pair[0], pair[1].max(pair[0])))
            .collect();
        intervals.sort_unstable();
        let ms = |ticks: u64| ticks as f64 * ns_per_tick * 1e-6;
        let mut busy = 0u64;
        let mut longest_gap = 0u64;
        let mut covered: Option<(u64, u64)> = None;
        for (begin, end) in intervals.iter().copied() {
            covered = Some(match covered {
                Some((start, until)) if begin <= until => (start, until.max(end)),
                Some((start, until)) => {
                    busy += until - start;
                    longest_gap = longest_gap.max(begin - until);
                    (begin, end)
                }
                None => (begin, end),
            });
        }
        if let Some((start, until)) = covered {
            busy += until - start;
        }
        let span = match (
            intervals.first(),
            intervals.iter().map(|&(_, end)| end).max(),
        ) {
            (Some(&(first, _)), Some(last)) => last - first,
            _ => 0,
        };
        Self {
            passes: intervals.len() as u32,
            untimed_passes,
            busy_ms: ms(busy),
            span_ms: ms(span),
            longest_gap_ms: ms(longest_gap),
        }
    }

    /// `busy_ms / span_ms` (1 for a timeline with no length).
    pub fn busy_fraction(&self) -> f64 {
        if self.span_ms <= 0.0 {
            return 1.0;
        }
        (self.busy_ms / self.span_ms).min(1.0)
    }

    /// Milliseconds of the span with no pass running.
    pub fn idle_ms(&self) -> f64 {
        (self.span_ms - self.busy_ms).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_between_passes_are_idle_and_overlaps_count_once() {
        // Passes [0, 10], [10, 30], [25, 40] (overlapping), then a gap to [100, 110]; given out
        // of order.
        let ticks = [100, 110, 0, 10, 25, 40, 10, 30];
        let timeline = PassTimeline::from_ticks(&ticks, 1e6, 2);
        assert_eq!(timeline.passes, 4);
        assert_eq!(timeline.untimed_passes, 2);
        assert!((timeline.span_ms - 110.0).abs() < 1e-9);
        assert!((timeline.busy_ms - 50.0).abs() < 1e-9);
        assert!((timeline.longest_gap_ms - 60.0).abs() < 1e-9);
        assert!((timeline.idle_ms() - 60.0).abs() < 1e-9);
        assert!((timeline.busy_fraction() - 50.0 / 110.0).abs() < 1e-12);
    }

    #[test]
    fn back_to_back_passes_are_fully_busy_and_an_empty_timeline_is_not_idle() {
        let timeline = PassTimeline::from_ticks(&[0, 5, 5, 9, 9, 20], 1.0, 0);
        assert_eq!(timeline.busy_fraction(), 1.0);
        assert_eq!(timeline.longest_gap_ms, 0.0);
        let empty = PassTimeline::from_ticks(&[], 1.0, 0);
        assert_eq!(empty.passes, 0);
        assert_eq!(empty.busy_fraction(), 1.0);
        // An end before its begin (a broken timestamp) counts as an empty pass.
        let broken = PassTimeline::from_ticks(&[10, 5], 1.0, 0);
        assert_eq!(broken.busy_ms, 0.0);
    }
}
