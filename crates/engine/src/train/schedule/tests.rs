//! The schedule's rules pinned down: the recipe kept exactly at its own length, the rest scaled.

use super::*;

fn defaults(steps: u32) -> TrainSchedule {
    TrainSchedule::resolve(&TrainConfig {
        steps,
        deformation: Some(DeformationConfig::default()),
        ..TrainConfig::default()
    })
}

#[test]
fn thirty_thousand_steps_keep_the_recipe_exactly() {
    let schedule = defaults(30_000);
    assert_eq!(schedule.densify_from, 500);
    assert_eq!(schedule.densify_until, 15_000);
    assert_eq!(schedule.densify_interval, 100);
    assert_eq!(schedule.opacity_reset_interval, 3_000);
    assert_eq!(schedule.sh_degree_interval, 1_000);
    assert_eq!(schedule.position_decay_steps, 30_000);
    let deformation = schedule.deformation.expect("dynamic");
    assert_eq!(deformation.warm_up_steps, 3_000);
    assert_eq!(deformation.learning_rate_decay_steps, 40_000);
    assert_eq!(deformation.time_noise_steps, 20_000);
    // The same stages as the fixed recipe: densify 500, 600, ... 14900; reset 3000 ... 12000.
    let densify: Vec<u32> = schedule.densify_steps().collect();
    assert_eq!(densify.first(), Some(&500));
    assert_eq!(densify.last(), Some(&14_900));
    assert_eq!(densify.len(), 145);
    let resets: Vec<u32> = schedule.reset_steps().collect();
    assert_eq!(resets, vec![3_000, 6_000, 9_000, 12_000]);
    for schedule in [schedule, schedule.for_random_init()] {
        assert!(!schedule.prunes_oversized_at(3_000) && schedule.prunes_oversized_at(3_001));
    }
    assert_eq!(schedule.sh_degree_at(999), 0);
    assert_eq!(schedule.sh_degree_at(3_000), 3);
    assert!(schedule.warnings().is_empty());
}

#[test]
fn plain_jobs_start_coarse_and_end_at_full_resolution() {
    let schedule = defaults(500);
    assert_eq!(schedule.coarse_until, 250);
    assert_eq!(schedule.resolution_divisor_at(0), 2);
    assert_eq!(schedule.resolution_divisor_at(249), 2);
    assert_eq!(schedule.resolution_divisor_at(250), 1);
    assert_eq!(schedule.resolution_divisor_at(499), 1);
    assert_eq!(defaults(100).coarse_until, 50);
    assert_eq!(defaults(30_000).coarse_until, MAX_DEFAULT_COARSE_STEPS);
    // Two halvings: a quarter, then half, then full resolution.
    let two = TrainSchedule::resolve(&TrainConfig {
        steps: 1_000,
        coarse_until: Some(600),
        coarse_halvings: 2,
        ..TrainConfig::default()
    });
    let divisors: Vec<u32> = [0, 299, 300, 599, 600]
        .map(|step| two.resolution_divisor_at(step))
        .to_vec();
    assert_eq!(divisors, vec![4, 4, 2, 2, 1]);
    // Never into the settle margin, never with the object loss, and 0 turns it off.
    let long = TrainSchedule::resolve(&TrainConfig {
        steps: 1_000,
        coarse_until: Some(5_000),
        ..TrainConfig::default()
    });
    assert_eq!(long.coarse_until, 1_000 - settle_margin(1_000));
    let objects = TrainSchedule::resolve(&TrainConfig {
        steps: 1_000,
        object_loss: Some(Default::default()),
        ..TrainConfig::default()
    });
    assert_eq!(objects.resolution_divisor_at(0), 1);
    let off = TrainSchedule::resolve(&TrainConfig {
        steps: 1_000,
        coarse_until: Some(0),
        ..TrainConfig::default()
    });
    assert_eq!((off.coarse_until, off.resolution_divisor_at(0)), (0, 1));
}

#[test]
fn a_short_job_densifies_more_than_once_and_settles_before_the_end() {
    let schedule = defaults(500);
    let densify: Vec<u32> = schedule.densify_steps().collect();
    assert_eq!(densify, vec![100, 200], "densifies at {densify:?}");
    let margin = settle_margin(500);
    assert!(margin >= 50);
    assert!(
        densify.iter().all(|&step| step + margin <= 500),
        "{densify:?}"
    );
    assert!(schedule.reset_steps().all(|step| step + margin <= 500));
    // No reset fits in 500 steps, so from sparse points nothing oversized is pruned; from
    // random points oversized splats are pruned after the first tenth.
    assert_eq!(schedule.reset_steps().count(), 0);
    assert!(!schedule.prunes_oversized_at(499));
    let random = schedule.for_random_init();
    assert!(!random.prunes_oversized_at(50) && random.prunes_oversized_at(51));
    // Every SH band is reached well before the end.
    assert_eq!(schedule.sh_degree_at(100), 3);
    assert_eq!(schedule.position_decay_steps, 500);
    assert!(schedule.warnings().is_empty(), "{:?}", schedule.warnings());
}

#[test]
fn explicit_values_win_but_never_inside_the_settle_margin() {
    let config = TrainConfig {
        steps: 1_000,
        densify_from: Some(100),
        densify_until: Some(1_000),
        densify_interval: Some(100),
        opacity_reset_interval: Some(0),
        sh_degree_interval: Some(250),
        ..TrainConfig::default()
    };
    let schedule = TrainSchedule::resolve(&config);
    assert_eq!(schedule.sh_degree_interval, 250);
    let densify: Vec<u32> = schedule.densify_steps().collect();
    assert_eq!(densify, vec![100, 200, 300, 400, 500, 600, 700, 800, 900]);
    assert_eq!(schedule.reset_steps().count(), 0);
    assert!(
        !schedule.for_random_init().prunes_oversized_at(900),
        "no reset configured: nothing pruned for its size"
    );
}

#[test]
fn a_sparse_capture_resets_no_opacity_and_keeps_its_large_splats_unless_asked() {
    let schedule = defaults(5_000);
    assert_eq!(schedule.reset_steps().count(), 2);
    let sparse = schedule.for_sparse_capture(None, true);
    assert_eq!(sparse.reset_steps().count(), 0);
    assert_eq!(
        sparse.densify_steps().count(),
        schedule.densify_steps().count()
    );
    assert!(!sparse.prunes_oversized_at(4_000));
    // From random points the early pruning stays: it is what removes their floaters.
    let random = schedule.for_random_init().for_sparse_capture(None, false);
    assert_eq!(random.reset_steps().count(), 0);
    assert!(!random.prunes_oversized_at(500) && random.prunes_oversized_at(501));
    let asked = TrainSchedule::resolve(&TrainConfig {
        steps: 5_000,
        opacity_reset_interval: Some(1_000),
        ..TrainConfig::default()
    });
    let kept = asked.for_sparse_capture(Some(1_000), true);
    assert_eq!(kept.reset_steps().count(), 2);
    assert!(kept.prunes_oversized_at(1_001));
}

#[test]
fn a_sparse_capture_densifies_for_fifty_passes_unless_the_config_says_when() {
    let schedule = defaults(10_000);
    assert_eq!(schedule.densify_until, 5_000);
    let sparse = schedule.densify_within_passes(None, 20);
    assert_eq!(sparse.densify_until, 1_000);
    assert_eq!(
        sparse.densify_steps().last(),
        Some(900),
        "before densify_until"
    );
    assert_eq!(schedule.densify_within_passes(Some(5_000), 20), schedule);
    // A short job keeps the recipe's earlier end.
    let short = defaults(2_000);
    assert_eq!(short.densify_within_passes(None, 20), short);
}

#[test]
fn a_longer_run_keeps_its_laid_out_stages_and_polishes_after_them() {
    let laid_out = |steps: u32, schedule_steps: Option<u32>| {
        TrainSchedule::resolve(&TrainConfig {
            steps,
            schedule_steps,
            deformation: Some(DeformationConfig::default()),
            ..TrainConfig::default()
        })
    };
    let scene = defaults(3_000);
    let longer = laid_out(15_000, Some(3_000));
    assert_eq!((longer.steps, longer.laid_out_over), (15_000, 3_000));
    // Every stage is where the 3000-step job has it.
    assert_eq!(
        TrainSchedule {
            steps: 3_000,
            ..longer
        },
        scene
    );
    assert!(longer.densify_steps().eq(scene.densify_steps()));
    // Full rates through the laid-out steps, a hundredth once as many again have passed.
    for step in [0, 1_000, 2_999] {
        assert_eq!(longer.polish_factor_at(step), 1.0);
        assert_eq!(scene.polish_factor_at(step), 1.0);
    }
    assert!((longer.polish_factor_at(4_500) - 0.1).abs() < 1e-4);
    for step in [6_000, 9_000, 15_000] {
        assert!((longer.polish_factor_at(step) - POLISH_FINAL_SHARE).abs() < 1e-6);
    }
    // Left out, or longer than the job: laid out over the job itself, no polish.
    for schedule_steps in [None, Some(15_000), Some(40_000)] {
        let whole = laid_out(15_000, schedule_steps);
        assert_eq!(whole, defaults(15_000), "{schedule_steps:?}");
        assert_eq!(whole.polish_factor_at(14_999), 1.0);
    }
}

#[test]
fn the_dynamic_warm_up_scales_with_the_job() {
    for (steps, warm_up) in [(600, 60), (3_000, 300), (30_000, 3_000), (60_000, 6_000)] {
        let deformation = defaults(steps).deformation.expect("dynamic");
        assert_eq!(deformation.warm_up_steps, warm_up, "{steps} steps");
        assert!(deformation.active_at(warm_up) && !deformation.active_at(warm_up - 1));
        assert!(defaults(steps).warnings().is_empty());
    }
}

#[test]
fn impossible_stages_are_named() {
    let config = TrainConfig {
        steps: 600,
        sh_degree_interval: Some(1_000),
        densify_from: Some(700),
        deformation: Some(DeformationConfig {
            warm_up_steps: Some(3_000),
            ..DeformationConfig::default()
        }),
        ..TrainConfig::default()
    };
    let warnings = TrainSchedule::resolve(&config).warnings();
    assert_eq!(warnings.len(), 3, "{warnings:?}");
    assert!(warnings[0].contains("densification never runs"));
    assert!(warnings[1].contains("SH degree stays 0"));
    assert!(warnings[2].contains("deformation field never trains"));
}
