//! When each stage of training happens, as a function of the job's length.
//!
//! The 3DGS recipe's constants are absolute and tuned for 30,000 steps: densify every 100 steps
//! from step 500 to 15,000, one more SH band every 1,000, opacity reset every 3,000, position
//! learning rate decaying over 30,000 and, for dynamic scenes (Deformable 3DGS), a 3,000-step
//! warm-up before the deformation field trains. Applied to a 500-step job they densify once, at
//! the last step, and never raise the SH degree; a dynamic job under 3,000 steps never trains its
//! field. Here every value a config leaves out is the 30k value scaled by `steps / 30000`, as
//! gsplat's `steps_scaler` scales its refine / reset / SH intervals, so a 30k-step job keeps
//! exactly the recipe, within floors that keep short jobs sensible (densification statistics
//! need several views, an opacity reset needs time to recover). Values a config gives are kept.
//! Either way nothing densifies or resets opacity in the last [`settle_margin`] steps, so the
//! model that is evaluated has trained after its last re-layout.
//!
//! Coarse to fine (not in the recipe; DashGaussian schedules resolution in the same spirit): the
//! first steps of a plain job, half of them up to [`MAX_DEFAULT_COARSE_STEPS`], render the
//! training views at half resolution ([`TrainSchedule::resolution_divisor_at`]). Those steps fit
//! the initial Gaussians' colours, sizes and places to the scene's coarse structure, which a
//! half-resolution image carries at a quarter of the pixels, so they cost about half a full step.
//! That fit takes a few hundred steps whatever the job's length, and a longer coarse phase costs
//! detail (densification then judges blurred images), so the default phase is capped; the rest,
//! and always the settle margin, train at full resolution.

use serde::Serialize;

use crate::deform::DeformationConfig;
use crate::train::TrainConfig;

/// The job length the 3DGS constants were tuned for.
pub const RECIPE_STEPS: u32 = 30_000;

/// The recipe's values at [`RECIPE_STEPS`] (3DGS; Deformable 3DGS for the field).
pub const RECIPE_DENSIFY_FROM: u32 = 500;
pub const RECIPE_DENSIFY_UNTIL: u32 = 15_000;
pub const RECIPE_DENSIFY_INTERVAL: u32 = 100;
pub const RECIPE_OPACITY_RESET_INTERVAL: u32 = 3_000;
pub const RECIPE_SH_DEGREE_INTERVAL: u32 = 1_000;
pub const RECIPE_POSITION_DECAY_STEPS: u32 = 30_000;
pub const RECIPE_WARM_UP_STEPS: u32 = 3_000;
pub const RECIPE_FIELD_DECAY_STEPS: u32 = 40_000;
pub const RECIPE_TIME_NOISE_STEPS: u32 = 20_000;

/// Share of a plain job's steps that train at reduced resolution by default, up to
/// [`MAX_DEFAULT_COARSE_STEPS`] (see the module doc; figures in docs/benchmarks.md,
/// "Coarse-to-fine steps").
pub const DEFAULT_COARSE_FRACTION: f64 = 0.5;
/// Most coarse steps by default. On the figurine at 256 px, half of a 500-step job coarse kept
/// its held-out PSNR within the seeds' spread (18.97 dB against 19.07, mean of three seeds) at
/// 1.28-1.41x the step rate; half of a 2000-step job coarse lost about 0.5 dB, 250 steps did not
/// measurably.
pub const MAX_DEFAULT_COARSE_STEPS: u32 = 250;

/// Fewest steps between two default densifications: each one judges the gradients accumulated
/// since the last, which should come from several training views (the recipe's 100 is kept for
/// every job up to 30k steps). On the figurine at 500 steps a floor of 50 (densifying at 50, 100,
/// 150, 200) ended with 9.8k Gaussians and 19.11 dB, 100 (at 100 and 200) with 5.3k and 19.00
/// dB at about 1.5x its step rate (docs/benchmarks.md).
pub const MIN_DENSIFY_INTERVAL: u32 = 100;
/// Fewest steps between two default opacity resets: every reset costs the scene its opacities,
/// which take hundreds of steps to come back.
pub const MIN_OPACITY_RESET_INTERVAL: u32 = 1_000;
/// Share of the job, at its end, in which nothing densifies or resets opacity.
pub const SETTLE_FRACTION: f64 = 0.1;
/// Captures with fewer training views than this are sparse: no default opacity reset
/// ([`TrainSchedule::for_sparse_capture`]).
pub const SPARSE_CAPTURE_VIEWS: usize = 100;

/// Passes over the training views after which a sparse capture stops densifying
/// ([`TrainSchedule::densify_within_passes`]).
pub const SPARSE_DENSIFY_PASSES: u32 = 50;

/// Share of its rate every parameter group keeps once a run longer than its schedule
/// (`TrainConfig::schedule_steps`) has polished for as many steps again.
pub const POLISH_FINAL_SHARE: f32 = 0.01;

/// `value` (tuned for [`RECIPE_STEPS`]) scaled to a job of `steps`, rounded; exact at 30k.
pub fn scaled(value: u32, steps: u32) -> u32 {
    let scaled = (value as u64 * steps as u64 + RECIPE_STEPS as u64 / 2) / RECIPE_STEPS as u64;
    scaled.min(u32::MAX as u64) as u32
}

/// Steps at the end of a job of `steps` in which nothing densifies or resets opacity.
pub fn settle_margin(steps: u32) -> u32 {
    (steps as f64 * SETTLE_FRACTION).ceil() as u32
}

/// The resolved schedule of one job: every stage boundary in steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct TrainSchedule {
    pub steps: u32,
    /// The steps the stages below are laid out over (`TrainConfig::schedule_steps`, at most
    /// `steps`). Steps past it polish: every learning rate decays ([`Self::polish_factor_at`]).
    pub laid_out_over: u32,
    pub densify_from: u32,
    pub densify_until: u32,
    pub densify_interval: u32,
    /// 0: no opacity reset.
    pub opacity_reset_interval: u32,
    /// Densifications after this step also prune oversized splats (0: never).
    pub prune_oversized_after: u32,
    pub sh_degree_interval: u32,
    pub max_sh_degree: u32,
    pub position_decay_steps: u32,
    pub settle_margin: u32,
    /// Steps before this one render at reduced resolution (0: none). Always 0 with the object
    /// loss, whose object masks are at the training resolution.
    pub coarse_until: u32,
    /// Halvings of the coarse steps: the coarse steps split evenly into this many stages, the
    /// first at `2^coarse_halvings` times smaller, each next stage at twice the last's resolution.
    pub coarse_halvings: u32,
    /// Present for a dynamic scene's job.
    pub deformation: Option<DeformationSchedule>,
}

/// When the deformation field trains, in steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct DeformationSchedule {
    /// Steps trained as a static scene before the field moves Gaussians.
    pub warm_up_steps: u32,
    /// Steps over which the field's learning rate decays.
    pub learning_rate_decay_steps: u32,
    /// Steps over which the time noise anneals to zero.
    pub time_noise_steps: u32,
}

impl DeformationSchedule {
    /// The config's values, or the recipe's scaled to `steps`.
    pub fn resolve(config: &DeformationConfig, steps: u32) -> Self {
        Self {
            warm_up_steps: config
                .warm_up_steps
                .unwrap_or_else(|| scaled(RECIPE_WARM_UP_STEPS, steps)),
            learning_rate_decay_steps: config
                .learning_rate_decay_steps
                .unwrap_or_else(|| scaled(RECIPE_FIELD_DECAY_STEPS, steps).max(1)),
            time_noise_steps: config
                .time_noise_steps
                .unwrap_or_else(|| scaled(RECIPE_TIME_NOISE_STEPS, steps)),
        }
    }

    /// Whether the field moves Gaussians in step `step` (0-based count of finished steps).
    pub fn active_at(&self, step: u32) -> bool {
        step >= self.warm_up_steps
    }
}

impl TrainSchedule {
    /// The schedule of `config`: its own values where it gives them, else the recipe's scaled to
    /// its `steps` (see the module documentation).
    pub fn resolve(config: &TrainConfig) -> Self {
        let job_steps = config.steps.max(1);
        // Every default below is laid out over these; a longer job polishes after them.
        let steps = config.laid_out_steps();
        let densify_interval = config.densify_interval.unwrap_or_else(|| {
            scaled(RECIPE_DENSIFY_INTERVAL, steps).max(MIN_DENSIFY_INTERVAL.min(steps))
        });
        let densify_from = config
            .densify_from
            .unwrap_or_else(|| scaled(RECIPE_DENSIFY_FROM, steps).max(densify_interval));
        let densify_until = config
            .densify_until
            .unwrap_or_else(|| scaled(RECIPE_DENSIFY_UNTIL, steps));
        let opacity_reset_interval = config.opacity_reset_interval.unwrap_or_else(|| {
            scaled(RECIPE_OPACITY_RESET_INTERVAL, steps).max(MIN_OPACITY_RESET_INTERVAL)
        });
        let sh_degree_interval = config
            .sh_degree_interval
            .unwrap_or_else(|| scaled(RECIPE_SH_DEGREE_INTERVAL, steps).max(1));
        let position_decay_steps = config
            .learning_rates
            .position_decay_steps
            .unwrap_or_else(|| scaled(RECIPE_POSITION_DECAY_STEPS, steps).max(1));
        let settle = settle_margin(steps);
        let coarse_until = if config.object_loss.is_some() || config.coarse_halvings == 0 {
            0
        } else {
            config
                .coarse_until
                .unwrap_or_else(|| {
                    ((steps as f64 * DEFAULT_COARSE_FRACTION).round() as u32)
                        .min(MAX_DEFAULT_COARSE_STEPS)
                })
                .min(steps.saturating_sub(settle))
        };
        Self {
            steps: job_steps,
            laid_out_over: steps,
            densify_from,
            densify_until,
            densify_interval: densify_interval.max(1),
            opacity_reset_interval,
            // 3DGS prunes oversized splats from its first opacity reset on.
            prune_oversized_after: opacity_reset_interval,
            sh_degree_interval: sh_degree_interval.max(1),
            max_sh_degree: config.max_sh_degree,
            position_decay_steps,
            settle_margin: settle,
            coarse_until,
            coarse_halvings: if coarse_until == 0 {
                0
            } else {
                config.coarse_halvings
            },
            deformation: config
                .deformation
                .as_ref()
                .map(|deformation| DeformationSchedule::resolve(deformation, steps)),
        }
    }

    /// The last step after which densification or an opacity reset may run.
    fn last_relayout_step(&self) -> u32 {
        self.laid_out_over.saturating_sub(self.settle_margin)
    }

    /// What every learning rate is multiplied by in step `step` (steps done so far): 1 within
    /// the laid-out steps, then an exponential decay to [`POLISH_FINAL_SHARE`] over as many
    /// steps again, held from there. The released schedule keeps its SH, opacity, scale and
    /// rotation rates constant to the end, which over a run five times longer than a sparse
    /// capture needs fits each training view's noise (figurine, seed 42, 256 px: 20.84 dB held
    /// out after the scene's 3000 steps, 18.97 after 15,000 at those rates, 21.13 polished;
    /// docs/segment_then_splat.md).
    pub fn polish_factor_at(&self, step: u32) -> f32 {
        if step < self.laid_out_over {
            return 1.0;
        }
        crate::schedule::exponential_decay(
            1.0,
            POLISH_FINAL_SHARE,
            step - self.laid_out_over,
            self.laid_out_over,
        )
    }

    /// Whether densification runs after `step` (1-based count of finished steps).
    pub fn densifies_at(&self, step: u32) -> bool {
        step >= self.densify_from
            && step < self.densify_until
            && step <= self.last_relayout_step()
            && step.is_multiple_of(self.densify_interval)
    }

    /// Whether the opacity reset runs after `step`.
    pub fn resets_opacity_at(&self, step: u32) -> bool {
        self.opacity_reset_interval > 0
            && step < self.densify_until
            && step <= self.last_relayout_step()
            && step.is_multiple_of(self.opacity_reset_interval)
    }

    /// This schedule for a scene whose initial Gaussians are random points (no sparse points):
    /// oversized splats are pruned from the recipe's first reset scaled to the job (a tenth of
    /// it), without the reset interval's floor. Random initial Gaussians have no surface under
    /// them; the ones the optimiser grows into blobs in front of a camera, to paint that one
    /// view, are never pruned in a job shorter than the floor. On a synthetic capture without
    /// points (1000 steps, seeds 42 / 0 / 1) this took held-out PSNR from 12-21 dB to about
    /// 35 dB (docs/benchmarks.md, "Random initial Gaussians and floaters"). A scene from
    /// sparse points keeps the recipe: there, pruning that early cost the figurine 3.8 dB at 500
    /// steps (its large far-background splats are real).
    pub fn for_random_init(mut self) -> Self {
        if self.prune_oversized_after > 0 {
            self.prune_oversized_after = self
                .prune_oversized_after
                .min(scaled(RECIPE_OPACITY_RESET_INTERVAL, self.steps).max(1));
        }
        self
    }

    /// This schedule for a sparse capture (fewer than [`SPARSE_CAPTURE_VIEWS`] training views):
    /// no opacity reset unless the config sets `opacity_reset_interval` (`configured`), and,
    /// for a scene from sparse points (`from_points`), no pruning of oversized splats either,
    /// which the recipe ties to the first reset (a scene from random points keeps
    /// [`Self::for_random_init`]'s early pruning, which is what removes its floaters). Both
    /// made longer training worse on the figurine (20 views, 256 px, Gaussian budget 8.6k):
    /// 3000 steps with a reset and pruning from step 1000 reached 17.9 dB held out, 4000 steps
    /// with the pruning alone fell from 19.6 dB at step 1000 to 13.3 at 2000 and 17.0 at the
    /// end, while 3000 steps with neither held 19.5 dB at steps 1000, 2000 and 3000
    /// (docs/benchmarks.md, "The Gaussian budget and steps from the scene"). After a reset every
    /// Gaussian is nearly transparent and with few views the opacities grow back wherever one
    /// view's pixels ask, as floaters in front of the others; and the figurine's large
    /// far-background splats are real.
    pub fn for_sparse_capture(mut self, configured: Option<u32>, from_points: bool) -> Self {
        if configured.is_none() {
            self.opacity_reset_interval = 0;
            if from_points {
                self.prune_oversized_after = 0;
            }
        }
        self
    }

    /// This schedule with densification ending after [`SPARSE_DENSIFY_PASSES`] passes over
    /// the `train_views` training views at the latest, unless the config sets `densify_until`
    /// (`configured`). Applied to sparse captures: once the model fills its Gaussian budget,
    /// densification only swaps the Gaussians it prunes for new clones and splits with fresh
    /// optimiser state, and on the figurine (20 views, 256 px, budget 8.6k, full by step 1000)
    /// that churn until the recipe's step 5000 of 10,000 cost 0.6 dB held out by the end
    /// (19.72 dB at step 4000, 19.07 at 10,000), while stopping at step 1000 (50 passes) held
    /// 20.2-20.35 dB from step 2000 to 10,000. Ending it as soon as the budget was full (by
    /// step ~300 of 10,000) was worse: 18.1-18.8 dB (docs/benchmarks.md, "The Gaussian budget
    /// and steps from the scene").
    pub fn densify_within_passes(mut self, configured: Option<u32>, train_views: usize) -> Self {
        if configured.is_none() {
            let passes = SPARSE_DENSIFY_PASSES.saturating_mul(train_views as u32);
            self.densify_until = self.densify_until.min(passes.max(self.densify_from));
        }
        self
    }

    /// Whether densification after `step` also prunes oversized splats.
    pub fn prunes_oversized_at(&self, step: u32) -> bool {
        self.prune_oversized_after > 0 && step > self.prune_oversized_after
    }

    /// Active SH degree in step `step` (0-based): one more band every `sh_degree_interval`.
    pub fn sh_degree_at(&self, step: u32) -> u32 {
        crate::schedule::sh_degree_at(step, self.sh_degree_interval, self.max_sh_degree)
    }

    /// How many times smaller each way the training views render at `step` (steps done so far,
    /// as [`Self::sh_degree_at`]): `2^coarse_halvings` in the first coarse stage, 1 from
    /// `coarse_until` on.
    pub fn resolution_divisor_at(&self, step: u32) -> u32 {
        if step >= self.coarse_until || self.coarse_halvings == 0 {
            return 1;
        }
        let stage = (step as u64 * self.coarse_halvings as u64 / self.coarse_until as u64) as u32;
        1 << (self.coarse_halvings - stage.min(self.coarse_halvings - 1))
    }

    /// The steps after which densification runs.
    pub fn densify_steps(&self) -> impl Iterator<Item = u32> + '_ {
        (1..=self.steps).filter(|&step| self.densifies_at(step))
    }

    /// The steps after which opacities are reset.
    pub fn reset_steps(&self) -> impl Iterator<Item = u32> + '_ {
        (1..=self.steps).filter(|&step| self.resets_opacity_at(step))
    }

    /// Stages the config asks for that this job cannot reach, in words (empty when all can).
    pub fn warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        let steps = self.steps;
        if self.densify_until > 0 && self.densify_steps().next().is_none() {
            warnings.push(format!(
                "densification never runs: it starts at step {} (every {} steps, before step {}) \
                 and nothing densifies in the last {} of the {steps} steps",
                self.densify_from, self.densify_interval, self.densify_until, self.settle_margin
            ));
        }
        if self.max_sh_degree > 0 && self.sh_degree_interval >= steps {
            warnings.push(format!(
                "the SH degree stays 0: one more band every {} steps, the job has {steps}",
                self.sh_degree_interval
            ));
        } else if self.max_sh_degree > 0
            && self.sh_degree_interval.saturating_mul(self.max_sh_degree) >= steps
        {
            warnings.push(format!(
                "SH degree {} is never reached: one more band every {} steps, the job has {steps}",
                self.max_sh_degree, self.sh_degree_interval
            ));
        }
        if let Some(deformation) = &self.deformation
            && deformation.warm_up_steps >= steps
        {
            warnings.push(format!(
                "the deformation field never trains: its warm-up is {} steps, the job has \
                 {steps}; the scene trains static",
                deformation.warm_up_steps
            ));
        }
        warnings
    }
}

#[cfg(test)]
mod tests;
