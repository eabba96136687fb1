//! How many Gaussians densification may grow a scene to, when its config does not say.
//!
//! The 3DGS recipe bounds growth only by its gradient threshold and its schedule, tuned on
//! captures of a few hundred views. On a sparse capture that grows the model far past what its
//! pixels constrain: the figurine (20 training views) at 256 px grew to 76k Gaussians in 3000
//! steps and lost 1.7 dB held out against 1000 steps with 9k, while 3000 steps without any
//! densification kept 19.7 dB (issue 38). Extra Gaussians there fit one view's pixels and float
//! in front of the others. So the budget follows what the training views can pin down, their
//! pixels at the training resolution, in the spirit of DashGaussian's primitive budget and
//! Taming 3DGS's: a fixed number of Gaussians per training pixel, never below twice the
//! initial model. Densification fills it with the highest-gradient candidates
//! ([`crate::densify::plan_densification`]'s `max_new`). Figures: docs/benchmarks.md,
//! "The Gaussian budget".

/// Gaussians per training pixel (all training views, at the training resolution).
pub const GAUSSIANS_PER_TRAINING_PIXEL: f64 = 0.01;

/// The default budget of a scene whose training views hold `training_pixels` pixels, starting
/// from `initial` Gaussians: what the pixels pin down, but room to at least double the start,
/// so densification can still refine where the loss asks when the start (sparse points and the
/// background shell) is already as large as the pixels' share (small images: on 12 views of
/// 80x60 a budget of the start alone left the spheres' small objects unrefined, their masks'
/// IoU 0.27 against 0.81).
pub fn scene_gaussian_budget(training_pixels: u64, initial: usize) -> usize {
    let by_pixels = (training_pixels as f64 * GAUSSIANS_PER_TRAINING_PIXEL).round() as usize;
    by_pixels.max(initial.saturating_mul(2))
}

/// Random initial Gaussians per training pixel (all training views, at the training
/// resolution) when a scene without sparse points leaves `random_init_count` out: twice the
/// Gaussian budget's rate, since most random points land where no surface is and are pruned in
/// the first few hundred steps.
pub const RANDOM_INIT_PER_TRAINING_PIXEL: f64 = 0.02;
/// Fewest random initial Gaussians the scene-sized start uses (a few small views).
pub const MIN_RANDOM_INIT: usize = 5_000;
/// Most random initial Gaussians the scene-sized start uses on a GPU: the 3DGS recipe's
/// 100k, which it draws for 100 views of 800 x 800.
pub const MAX_RANDOM_INIT: usize = 100_000;
/// Most on a software (CPU) adapter, where every Gaussian of the first steps costs host time.
pub const MAX_RANDOM_INIT_SOFTWARE: usize = 20_000;

/// The random start of a scene without sparse points whose training views hold
/// `training_pixels` pixels: [`RANDOM_INIT_PER_TRAINING_PIXEL`] of them, within
/// [`MIN_RANDOM_INIT`] and [`MAX_RANDOM_INIT`] (or [`MAX_RANDOM_INIT_SOFTWARE`] on a software
/// adapter). Figures: docs/engine.md, "The random start".
pub fn scene_random_init_count(training_pixels: u64, software: bool) -> usize {
    let ceiling = if software {
        MAX_RANDOM_INIT_SOFTWARE
    } else {
        MAX_RANDOM_INIT
    };
    let by_pixels = (training_pixels as f64 * RANDOM_INIT_PER_TRAINING_PIXEL).round() as usize;
    by_pixels.clamp(MIN_RANDOM_INIT, ceiling)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_budget_follows_the_pixels_and_never_shrinks_the_start() {
        // 20 views at 256 x 168 and at 1000 x 658.
        assert_eq!(scene_gaussian_budget(20 * 256 * 168, 2_443), 8_602);
        assert_eq!(scene_gaussian_budget(20 * 1000 * 658, 2_443), 131_600);
        // A start as large as the pixels' share may still double.
        assert_eq!(scene_gaussian_budget(1_000, 5_000), 10_000);
    }

    #[test]
    fn the_random_start_follows_the_pixels_within_a_floor_and_a_ceiling() {
        // 20 views at 256 x 168: 17k; 12 views of 80 x 60: the floor.
        assert_eq!(scene_random_init_count(20 * 256 * 168, false), 17_203);
        assert_eq!(
            scene_random_init_count(12 * 80 * 60, false),
            MIN_RANDOM_INIT
        );
        // 100 views of 800 x 800: the recipe's 100k, a fifth of that on a software adapter.
        assert_eq!(
            scene_random_init_count(100 * 800 * 800, false),
            MAX_RANDOM_INIT
        );
        assert_eq!(
            scene_random_init_count(100 * 800 * 800, true),
            MAX_RANDOM_INIT_SOFTWARE
        );
        assert_eq!(scene_random_init_count(20 * 256 * 168, true), 17_203);
    }
}
