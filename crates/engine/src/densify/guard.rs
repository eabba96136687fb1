//! Vetoes on pruning: Segment then Splat's per-object persistence floor. A guard sees only what
//! it decides on (object ids and opacities), so the GPU densification pass can hand it those
//! two arrays instead of the whole model.

use std::collections::HashMap;

use crate::model::OBJECT_NONE;

/// What a [`PruneGuard`] decides on, for every Gaussian before densification.
#[derive(Debug, Clone, Copy)]
pub struct GuardInputs<'a> {
    pub object_ids: &'a [[u32; 3]],
    pub opacity_logits: &'a [f32],
}

/// Can veto pruning: set `prune[i] = false` to keep Gaussian `i`. `survivors_after_split[i]` is
/// how many Gaussians `i` turns into if kept (2 for a clone pair, the children of a split).
pub trait PruneGuard {
    fn spare(&self, inputs: GuardInputs<'_>, prune: &mut [bool], survivors_after_split: &[u32]);
}

/// Never lets an object (per level) fall below `floors[level]` Gaussians, or below its current
/// count if that is smaller: pruning candidates of a starving object are spared, most opaque
/// first. This is the persistence rule the released Segment-then-Splat code intended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectFloor {
    pub floors: [usize; 3],
}

impl PruneGuard for ObjectFloor {
    fn spare(&self, inputs: GuardInputs<'_>, prune: &mut [bool], survivors_after_split: &[u32]) {
        for level in 0..3 {
            let floor = self.floors[level];
            if floor == 0 {
                continue;
            }
            // Per object: Gaussians now, Gaussians that would remain, and its prune candidates.
            let mut current: HashMap<u32, usize> = HashMap::new();
            let mut remaining: HashMap<u32, usize> = HashMap::new();
            let mut candidates: HashMap<u32, Vec<usize>> = HashMap::new();
            for (index, ids) in inputs.object_ids.iter().enumerate() {
                let id = ids[level];
                if id == OBJECT_NONE {
                    continue;
                }
                *current.entry(id).or_default() += 1;
                if prune[index] {
                    candidates.entry(id).or_default().push(index);
                } else {
                    *remaining.entry(id).or_default() += survivors_after_split[index] as usize;
                }
            }
            for (id, mut indices) in candidates {
                let wanted = floor.min(current[&id]);
                let mut kept = remaining.get(&id).copied().unwrap_or(0);
                if kept >= wanted {
                    continue;
                }
                let opacity = inputs.opacity_logits;
                indices.sort_by(|&a, &b| opacity[b].total_cmp(&opacity[a]).then(a.cmp(&b)));
                for index in indices {
                    if kept >= wanted {
                        break;
                    }
                    prune[index] = false;
                    kept += survivors_after_split[index] as usize;
                }
            }
        }
    }
}
