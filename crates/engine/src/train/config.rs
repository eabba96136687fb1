//! Training configuration with 3DGS defaults (schedules scaled to the job's length); every field
//! can be set per job.

use serde::{Deserialize, Serialize};

use crate::deform::DeformationConfig;
use crate::densify::DensifyConfig;
use crate::schedule::LearningRates;
use crate::train::convergence::ConvergenceStop;
use crate::train::object_loss::ObjectLossConfig;
use crate::train::schedule::TrainSchedule;

/// Most halvings the coarse steps may use (a 16th of the resolution each way).
pub const MAX_COARSE_HALVINGS: u32 = 4;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Optimisation steps (one training view each).
    pub steps: u32,
    /// Steps the schedule's stages are laid out over (densification, SH bands, the position
    /// rate's decay, coarse steps, the deformation field's warm-up); `None` is `steps`. A run
    /// longer than this polishes what it laid out: from here every learning rate decays to
    /// [`crate::train::schedule::POLISH_FINAL_SHARE`] of its value over as many steps again, and
    /// stays there ([`crate::train::TrainSchedule::polish_factor_at`]). A job that asks for more
    /// steps than its scene needs gets the scene's steps here, so the extra steps cannot
    /// stretch its schedule into overfitting (docs/segment_then_splat.md, "Longer than the
    /// scene needs").
    pub schedule_steps: Option<u32>,
    /// Longest image side in pixels; images are downscaled to it (never upscaled).
    pub max_resolution: Option<u32>,
    /// Every n-th view (by capture order, starting with the first) is held out for evaluation,
    /// as 3DGS does with n = 8. 0 = train on all views. Datasets with their own split (Blender)
    /// use it instead.
    pub eval_split_every: u32,
    /// Seed of every random choice (initialisation, view order, densification samples).
    pub seed: u64,
    /// Background composited behind the splats (0..1 RGB).
    pub background: [f32; 3],
    /// Highest SH degree; one more band is enabled every `sh_degree_interval` steps.
    pub max_sh_degree: u32,
    /// Schedule values left out (`None`) are the 3DGS recipe's 30k-step values scaled to
    /// `steps` ([`crate::train::schedule`]); given values are kept.
    pub sh_degree_interval: Option<u32>,
    pub learning_rates: LearningRates,
    pub densify: DensifyConfig,
    /// Densify every `densify_interval` steps in [`densify_from`, `densify_until`).
    /// (never in the job's last tenth, the settle margin).
    pub densify_from: Option<u32>,
    pub densify_until: Option<u32>,
    pub densify_interval: Option<u32>,
    /// Every `opacity_reset_interval` steps (while densifying) opacities are capped at 0.01;
    /// 0 never resets.
    pub opacity_reset_interval: Option<u32>,
    /// Coarse to fine: steps before `coarse_until` render the training views at reduced
    /// resolution ([`crate::train::schedule`]); `None` is half the steps up to 250, 0 never, and
    /// it always ends before the settle margin. Off with the object loss.
    pub coarse_until: Option<u32>,
    /// Resolution halvings of the coarse steps (1: half resolution; 2: a quarter, then half).
    pub coarse_halvings: u32,
    /// Upper bound on Gaussians: densification stops growing past it.
    pub max_gaussians: usize,
    /// Gaussians densification may grow the model to; `None` sizes it from the scene (its
    /// training pixels, at least twice the start, [`crate::train::budget`]), so a sparse capture is not grown into
    /// floaters that fit each training view and no other. Always within `max_gaussians`.
    pub gaussian_budget: Option<usize>,
    /// Random initial Gaussians when the dataset has no sparse points; `None` sizes the start
    /// from the scene's training pixels and the adapter ([`crate::train::budget::scene_random_init_count`]),
    /// and the trainer's config then holds the count it chose.
    pub random_init_count: Option<usize>,
    /// Background Gaussians (no object) on a far sphere around the cameras and points, for the
    /// far background (sky, walls) the sparse points miss. Plain training adds them to a
    /// scene's sparse points (not to random initialisations); Segment then Splat to its voted
    /// model. 0: none.
    pub background_shell: usize,
    /// The Segment-then-Splat object loss; `None` trains plain 3DGS. It acts once the trainer
    /// is given object masks ([`crate::train::Trainer::set_object_targets`]).
    pub object_loss: Option<ObjectLossConfig>,
    /// The deformation field of a dynamic scene; `None` trains a static scene. Each view is
    /// rendered at its frame's time (0 when the frame has none).
    pub deformation: Option<DeformationConfig>,
    /// Ends the run before `steps` once the fit of a few training views stops gaining
    /// ([`crate::train::convergence`]; `steps` is then a ceiling); `None` trains every step.
    /// Off unless asked for: on the figurine the training views' fit kept gaining past the
    /// point where held-out quality levelled off (docs/benchmarks.md, "A convergence stop").
    pub stop_when_converged: Option<ConvergenceStop>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            steps: 30_000,
            schedule_steps: None,
            max_resolution: Some(1600),
            eval_split_every: 8,
            seed: 0,
            background: [0.0; 3],
            max_sh_degree: 3,
            sh_degree_interval: None,
            learning_rates: LearningRates::default(),
            densify: DensifyConfig::default(),
            densify_from: None,
            densify_until: None,
            densify_interval: None,
            opacity_reset_interval: None,
            coarse_until: None,
            coarse_halvings: 1,
            max_gaussians: 6_000_000,
            gaussian_budget: None,
            random_init_count: None,
            background_shell: crate::background_shell::DEFAULT_BACKGROUND_SHELL,
            object_loss: None,
            deformation: None,
            stop_when_converged: None,
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[error("train config: {field}: {problem}")]
pub struct ConfigError {
    pub field: &'static str,
    pub problem: String,
}

impl TrainConfig {
    /// Checks ranges; names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let fail = |field, problem: &str| {
            Err(ConfigError {
                field,
                problem: problem.to_string(),
            })
        };
        if self.steps == 0 {
            return fail("steps", "must be at least 1");
        }
        if self.schedule_steps == Some(0) {
            return fail("schedule_steps", "must be at least 1");
        }
        if self.max_resolution == Some(0) {
            return fail("max_resolution", "must be positive");
        }
        if self.max_sh_degree > 3 {
            return fail("max_sh_degree", "must be 0..=3");
        }
        if self.densify_interval == Some(0) {
            return fail("densify_interval", "must be at least 1");
        }
        if self.sh_degree_interval == Some(0) {
            return fail("sh_degree_interval", "must be at least 1");
        }
        if self.background.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return fail("background", "components must be within 0..=1");
        }
        let rates = &self.learning_rates;
        for (field, rate) in [
            ("learning_rates.position_initial", rates.position_initial),
            ("learning_rates.position_final", rates.position_final),
            ("learning_rates.sh_dc", rates.sh_dc),
            ("learning_rates.opacity", rates.opacity),
            ("learning_rates.scale", rates.scale),
            ("learning_rates.rotation", rates.rotation),
        ] {
            // A negative rate climbs the loss; NaN poisons every parameter.
            if !(rate.is_finite() && rate >= 0.0) {
                return fail(field, "must be a finite number >= 0");
            }
        }
        if !(rates.sh_rest_divisor.is_finite() && rates.sh_rest_divisor > 0.0) {
            return fail(
                "learning_rates.sh_rest_divisor",
                "must be a finite number > 0",
            );
        }
        if rates.position_decay_steps == Some(0) {
            return fail("learning_rates.position_decay_steps", "must be at least 1");
        }
        if !self.densify.gradient_threshold.is_finite() {
            return fail("densify.gradient_threshold", "must be a finite number");
        }
        if self.densify.gradient_threshold <= 0.0 {
            return fail("densify.gradient_threshold", "must be positive");
        }
        if self.coarse_halvings > MAX_COARSE_HALVINGS {
            return fail(
                "coarse_halvings",
                &format!("must be 0..={MAX_COARSE_HALVINGS}"),
            );
        }
        if self.max_gaussians == 0 {
            return fail("max_gaussians", "must be at least 1");
        }
        if self.gaussian_budget == Some(0) {
            return fail("gaussian_budget", "must be at least 1");
        }
        if let Some(object_loss) = &self.object_loss
            && let Err((field, problem)) = object_loss.validate()
        {
            return fail(field, &problem);
        }
        if let Some(deformation) = &self.deformation
            && let Err((field, problem)) = deformation.validate()
        {
            return fail(field, &problem);
        }
        if let Some(Err(problem)) = self.stop_when_converged.map(|stop| stop.validate()) {
            return fail("stop_when_converged", problem);
        }
        Ok(())
    }

    /// The steps the schedule is laid out over: `schedule_steps`, else `steps`, within 1 and
    /// `steps`.
    pub fn laid_out_steps(&self) -> u32 {
        let steps = self.steps.max(1);
        self.schedule_steps.unwrap_or(steps).clamp(1, steps)
    }

    /// When each stage runs in this job (defaults scaled to `steps`).
    pub fn schedule(&self) -> TrainSchedule {
        TrainSchedule::resolve(self)
    }
}
