//! Stage 1's tracking for unposed or dynamic sequences (docs/method.md stage 1, steps 2-4), where no 3D
//! evidence can carry identity: every object's mask is carried from frame to frame by prompting a
//! region segmenter (a SAM-family decoder) on the next frame with the previous mask.
//!
//! Per frame, every live object of every level is prompted with its last good mask (box, interior
//! points, and the segmenter's own low-resolution logits of the previous answer); answers are
//! accepted or the object is lost for that frame ([`PropagationOptions`] says when), and the
//! accepted masks are painted so that every pixel holds at most one object per level (`paint`).
//! Every `stride` frames the track set is checked: duplicate tracks are dropped (`duplicates`),
//! new objects are looked for when the uncovered share of a level grew (`new_objects`), and the
//! mask priors are cleared so the next frame is prompted from the current masks alone
//! (re-anchoring: errors fed back through the prior compound for at most `stride` frames).
//!
//! Tracks only run forward: an object found at a check appears from that frame on, and an object
//! lost for good ends; stage 2 merges tracks of one object that this split.

mod duplicates;
mod interior;
mod new_objects;
mod paint;
mod run;
mod track;

/// A synthetic moving-discs sequence with stand-in segmenters, for this module's tests and the
/// method crate's (feature `test-support`).
#[cfg(any(test, feature = "test-support"))]
pub mod test_support;
#[cfg(test)]
mod tests;

use crate::segment::{PromptError, SegmentError};
use segsplat_scene::Level;

pub use run::propagate_masks;

/// Why propagation stopped.
#[derive(Debug, thiserror::Error)]
pub enum PropagationError {
    #[error("propagation options: {field} {message}")]
    InvalidOptions {
        field: &'static str,
        message: String,
    },
    #[error("first-frame masks: {0}")]
    FirstFrame(String),
    #[error("cannot load frame {frame_index}: {source}")]
    LoadFrame {
        frame_index: usize,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    #[error("frame {frame_index} is {found:?}, the first frame's masks {expected:?}")]
    FrameSize {
        frame_index: usize,
        found: [u32; 2],
        expected: [u32; 2],
    },
    #[error("frame {frame_index}: {source}")]
    Prompt {
        frame_index: usize,
        #[source]
        source: PromptError,
    },
    #[error("frame {frame_index}: the segmenter gave {found} answers to {expected} prompts")]
    AnswerCount {
        frame_index: usize,
        expected: usize,
        found: usize,
    },
    #[error("frame {frame_index}: a mask is {found:?}, the frame {expected:?}")]
    MaskSize {
        frame_index: usize,
        found: [u32; 2],
        expected: [u32; 2],
    },
    #[error("frame {frame_index}: new-object masks: {source}")]
    NewObjects {
        frame_index: usize,
        #[source]
        source: SegmentError,
    },
}

/// The rules of propagation; every default is a choice stated here.
#[derive(Debug, Clone, PartialEq)]
pub struct PropagationOptions {
    /// Frames between checks (duplicates, new objects, re-anchoring); docs/method.md: 10.
    pub stride: usize,
    /// A new object must cover more than this many pixels at the sequence's full resolution
    /// (docs/method.md: 5000) ...
    pub new_object_min_area_at_full_res: f64,
    /// ... scaled by the square of this: frame pixels per full-resolution pixel along a side
    /// (0.5 when frames come at half size). Note `association` states its 5000 px at a
    /// 1000-pixel-wide image instead; callers that want that pass `width / 1000`.
    pub full_resolution_scale: f64,
    /// New objects are looked for when a level's uncovered share grew by more than this over its
    /// ratchet threshold (docs/method.md: 0.01; see `new_objects`).
    pub uncovered_growth: f64,
    /// A candidate is new when more than this share of its area is uncovered (docs/method.md: 0.5).
    pub new_object_uncovered_share: f64,
    /// Two tracks of one level whose IoU, pooled over the check frames where both were answered,
    /// is above this are one object; the smaller is dropped everywhere (docs/method.md: 0.5).
    pub duplicate_iou: f64,
    /// An answer whose predicted IoU is below this is no answer (0.5: SAM-family decoders put
    /// confident masks at 0.8-1; below one half the mask is a guess).
    pub min_predicted_iou: f32,
    /// An answer more than this many times the area of the object's last good mask is no answer
    /// (4: twice the size along each side in one frame; a larger jump is the decoder bleeding
    /// into the background or a neighbour). Shrinking is not limited: occlusion and leaving the
    /// frame shrink objects legitimately.
    pub max_area_growth: f64,
    /// An object without an accepted answer for more than this many consecutive frames ends; until
    /// then it is prompted from its last good mask, so it is found again after a short occlusion
    /// (10: one stride, by when a new-object check has looked at its place).
    pub max_lost_frames: usize,
    /// Prompts per segmenter call (the paper's 40 objects a batch).
    pub prompts_per_call: usize,
    /// Positive points per prompt: the interior point farthest from the mask's edge, then points
    /// spread over the mask's deep interior (3). Every prompt gets this many, so prompts batch.
    pub positive_points: usize,
    /// The prompt box is the previous mask's box grown by this fraction of its width / height on
    /// each side (0.1: room for a few pixels of motion without inviting neighbours in).
    pub box_margin: f32,
}

impl Default for PropagationOptions {
    fn default() -> Self {
        Self {
            stride: 10,
            new_object_min_area_at_full_res: 5000.0,
            full_resolution_scale: 1.0,
            uncovered_growth: 0.01,
            new_object_uncovered_share: 0.5,
            duplicate_iou: 0.5,
            min_predicted_iou: 0.5,
            max_area_growth: 4.0,
            max_lost_frames: 10,
            prompts_per_call: 40,
            positive_points: 3,
            box_margin: 0.1,
        }
    }
}

impl PropagationOptions {
    pub fn validate(&self) -> Result<(), PropagationError> {
        let invalid = |field: &'static str, message: String| {
            Err(PropagationError::InvalidOptions { field, message })
        };
        let fraction = |value: f64| (0.0..=1.0).contains(&value);
        if self.stride == 0 {
            return invalid("stride", "must be at least 1".to_string());
        }
        if self.prompts_per_call == 0 {
            return invalid("prompts_per_call", "must be at least 1".to_string());
        }
        if !(self.new_object_min_area_at_full_res.is_finite()
            && self.new_object_min_area_at_full_res >= 0.0)
        {
            return invalid(
                "new_object_min_area_at_full_res",
                format!(
                    "must be finite and >= 0, got {}",
                    self.new_object_min_area_at_full_res
                ),
            );
        }
        if !(self.full_resolution_scale.is_finite() && self.full_resolution_scale > 0.0) {
            return invalid(
                "full_resolution_scale",
                format!("must be finite and > 0, got {}", self.full_resolution_scale),
            );
        }
        for (field, value) in [
            ("uncovered_growth", self.uncovered_growth),
            (
                "new_object_uncovered_share",
                self.new_object_uncovered_share,
            ),
            ("duplicate_iou", self.duplicate_iou),
            ("min_predicted_iou", f64::from(self.min_predicted_iou)),
        ] {
            if !fraction(value) {
                return invalid(field, format!("must be within 0..=1, got {value}"));
            }
        }
        if !(self.max_area_growth.is_finite() && self.max_area_growth >= 1.0) {
            return invalid(
                "max_area_growth",
                format!("must be finite and >= 1, got {}", self.max_area_growth),
            );
        }
        if !(self.box_margin.is_finite() && self.box_margin >= 0.0) {
            return invalid(
                "box_margin",
                format!("must be finite and >= 0, got {}", self.box_margin),
            );
        }
        Ok(())
    }

    /// The smallest new object, in frame pixels (exclusive).
    pub fn new_object_min_area(&self) -> f64 {
        self.new_object_min_area_at_full_res * self.full_resolution_scale.powi(2)
    }
}

/// The masks propagation starts from: frame 0's instance ids per level (small, middle, large;
/// row-major, 0 = no object), e.g. `FrameMasks::instance_ids` of automatic masks. Their ids are
/// kept; new objects get ids above the largest.
#[derive(Debug, Clone, PartialEq)]
pub struct FirstFrameMasks {
    pub width: u32,
    pub height: u32,
    pub ids: [Vec<u32>; 3],
}

/// Per-frame instance ids of every level, one id per object for the whole sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct Propagation {
    pub width: u32,
    pub height: u32,
    /// `frames[i][level]`: frame `i`'s row-major ids at that level; 0 = no object.
    pub frames: Vec<[Vec<u32>; 3]>,
    pub report: PropagationReport,
}

/// What happened, for logs and job records.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PropagationReport {
    /// Objects frame 0 started with, per level.
    pub first_frame_objects: [usize; 3],
    /// Distinct ids in the output, per level.
    pub objects_per_level: [usize; 3],
    pub checks: Vec<ObjectCheck>,
    pub duplicates: Vec<DuplicateDrop>,
    /// Per level, frames in which a live object had no acceptable answer (summed over objects).
    pub lost_frames: [u64; 3],
    /// Per level, objects that ended after `max_lost_frames`.
    pub ended: [usize; 3],
    pub prompts: u64,
    pub segmenter_calls: u64,
}

/// One new-object check (every `stride` frames).
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectCheck {
    pub frame_index: usize,
    /// Uncovered share of each level before new objects were added.
    pub uncovered: [f64; 3],
    /// The ratchet thresholds it was compared with.
    pub thresholds: [f64; 3],
    /// Whether new-object masks were generated.
    pub detection_ran: bool,
    /// New objects added per level.
    pub new_objects: [usize; 3],
}

/// A track dropped as the duplicate of another.
#[derive(Debug, Clone, PartialEq)]
pub struct DuplicateDrop {
    pub level: Level,
    pub frame_index: usize,
    pub dropped: u32,
    pub kept: u32,
    /// Their IoU pooled over the checks where both were answered.
    pub iou: f64,
}
