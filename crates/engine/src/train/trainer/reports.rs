//! What a trainer reports while it runs (progress, held-out quality, the partial-mask filter's
//! cost) and what a checkpoint's header records of it.

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::train::config::TrainConfig;
use crate::train::object_loss::SkippedPair;
use crate::train::partial_filter_report::PartialFilterReport;

use super::ConvergedAt;

/// Reported every `SYNC_EVERY` steps (the trainer's read-back interval) and at the end.
#[derive(Debug, Clone, Serialize)]
pub struct TrainProgress {
    pub step: u32,
    pub total_steps: u32,
    /// Loss of the latest step (0.8 L1 + 0.2 D-SSIM).
    pub loss: f32,
    /// Sum of the latest step's weighted object losses (0 without the object loss).
    pub object_loss: f32,
    pub gaussians: usize,
    pub elapsed_secs: f64,
    pub steps_per_sec: f64,
}

/// Held-out quality.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct EvalReport {
    pub views: usize,
    /// Means over the held-out views.
    pub psnr: f64,
    pub ssim: f64,
    /// The worst held-out view's PSNR (floaters in front of a few cameras show here first), and
    /// its index among the held-out views (absent in reports written before they were kept).
    #[serde(default)]
    pub worst_psnr: f64,
    #[serde(default)]
    pub worst_view: usize,
    /// The worst held-out view as the scene knows it: its frame index among all the scene's
    /// frames and its name (absent in reports written before they were kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_frame_index: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_frame_name: Option<String>,
}

/// What a checkpoint's header records besides the arrays.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrainerMeta {
    pub step: u32,
    pub gaussians: usize,
    pub rng: ChaCha8Rng,
    pub view_queue: Vec<usize>,
    pub intersection_capacity: u32,
    pub config: TrainConfig,
    pub train_views: usize,
    /// (object, view) pairs the partial-mask filter has left out.
    #[serde(default)]
    pub skipped_pairs: Vec<SkippedPair>,
    /// The job's Gaussian budget (absent in checkpoints written before budgets: the resumed
    /// trainer then sizes it from the scene again, at least the checkpoint's count).
    #[serde(default)]
    pub gaussian_budget: Option<usize>,
    /// Where the convergence stop ended the run (a resumed run that had ended stays ended; the
    /// checks' history is not kept, so a run resumed before its stop refills its window).
    #[serde(default)]
    pub converged_at: Option<ConvergedAt>,
    /// What the partial-mask filter found, when it has run (absent in older checkpoints).
    #[serde(default)]
    pub partial_filter: Option<PartialFilterReport>,
}

/// Wall time and kernel dispatches the partial-mask filter has taken, inside [`Trainer::run`](super::Trainer::run)'s
/// time and the context's dispatch count.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PartialFilterCost {
    pub seconds: f64,
    pub dispatches: u64,
}
