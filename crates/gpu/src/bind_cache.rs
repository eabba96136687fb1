//! Bind groups made once and reused while their buffers stay the same.
//!
//! A training step binds the same buffers every step (they change only when the model grows or a
//! scratch buffer is enlarged), so each dispatch creating its bind group anew was pure host cost.
//! The cache is keyed by the kernel and the exact buffer ranges. An entry holds its buffers
//! alive, so entries not used for [`KEEP_SUBMISSIONS`] submissions are dropped, and the owners
//! of buffers that are replaced wholesale clear the cache when they replace them (densification
//! when it re-lays out the model, the mask renderer's scene cache when it evicts a scene).

use std::collections::HashMap;

/// Submissions an unused bind group survives. A view's loss binds that view's image, so its
/// groups come back once a pass over the training views: the window must outlast a pass, the
/// training views times the submissions of a step (a few; more for a dynamic step, whose field
/// runs in chunks). 256 would make a capture of a hundred views or more bind anew every step;
/// 4096 covers several hundred. A buffer replaced in between (a grown scratch buffer) is held
/// that long at most.
pub const KEEP_SUBMISSIONS: u64 = 4096;

/// One binding of a cached group: a buffer range (size `None`: to the end).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct BoundRange {
    pub buffer: wgpu::Buffer,
    pub offset: u64,
    pub size: Option<u64>,
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct BindKey {
    pub kernel: u64,
    pub ranges: Vec<BoundRange>,
}

#[derive(Debug)]
struct Cached {
    group: wgpu::BindGroup,
    last_used: u64,
}

#[derive(Debug, Default)]
pub struct BindGroupCache {
    entries: HashMap<BindKey, Cached>,
    submissions: u64,
}

impl BindGroupCache {
    /// The cached group for `key`, or the one `create` makes (then cached); `true` when it
    /// was made.
    pub fn get_or_create(
        &mut self,
        key: BindKey,
        create: impl FnOnce(&BindKey) -> wgpu::BindGroup,
    ) -> (wgpu::BindGroup, bool) {
        let now = self.submissions;
        if let Some(cached) = self.entries.get_mut(&key) {
            cached.last_used = now;
            return (cached.group.clone(), false);
        }
        let group = create(&key);
        self.entries.insert(
            key,
            Cached {
                group: group.clone(),
                last_used: now,
            },
        );
        (group, true)
    }

    /// Counts a submission and drops the groups unused for [`KEEP_SUBMISSIONS`] of them.
    pub fn after_submit(&mut self) {
        self.submissions += 1;
        let now = self.submissions;
        self.entries
            .retain(|_, cached| now - cached.last_used <= KEEP_SUBMISSIONS);
    }

    /// Drops every cached group (and with them the last references to freed buffers).
    pub fn clear(&mut self) {
        self.entries.clear();
    }
}
