//! Evaluation: image quality of held-out views, and open-vocabulary segmentation against the
//! LERF_OVS and 3D-OVS benchmark ground truth (loaders, mIoU as the papers compute it, and the
//! oracle that scores the 3D segmentation apart from language). Pure CPU code: no GPU, no store.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

pub mod error;
pub mod ground_truth;
mod lerf_ovs;
mod opencv_line;
pub mod polygon;
pub mod report_table;
pub mod resize;
pub mod scene_match;
pub mod segmentation_metrics;
mod three_d_ovs;

pub use error::EvalError;
pub use ground_truth::{GroundTruthFormat, GroundTruthFrame, GroundTruthQuery, load_ground_truth};
pub use report_table::report_table;
pub use resize::resize_nearest;
pub use scene_match::{SceneFrame, scene_mismatches};
pub use segmentation_metrics::{
    FrameQueryScore, FrameScore, SegmentationReport, evaluate, mask_iou, oracle_choice,
    score_frame, summarize,
};
