//! Short training runs on the synthetic scene: the held-out PSNR bar, a run past its schedule,
//! the Gaussian budget, steady steps that allocate nothing, coarse-to-fine steps, the convergence
//! stop, and the training views loaded the same on one thread and on several.

use segsplat_engine::schedule::LearningRates;
use segsplat_engine::train::convergence::ConvergenceStop;
use segsplat_engine::train::trainer::{initial_model, plain_initial_model};
use segsplat_engine::train::{TrainConfig, Trainer};

use crate::gpu_support::{self, new_gpu_context};
use crate::support::{config, synthetic_scene};

#[test]
fn short_training_reaches_held_out_psnr() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    // Start from the sparse points' positions only: every colour grey, so the colours, like the
    // geometry, must be learned through the gradients.
    let mut initial = initial_model(&scene, &config(500)).unwrap();
    for sh in &mut initial.sh_coefficients {
        sh[0] = [0.0; 3];
    }
    let mut trainer = Trainer::new(&ctx, &scene, config(500), Some(initial)).unwrap();
    assert_eq!(trainer.views().test.len(), 4);
    let initial_gaussians = trainer.gaussian_count();
    let before = trainer.evaluate().unwrap();
    let progress = trainer.run(|_| true).unwrap();
    let after = trainer.evaluate().unwrap();
    eprintln!(
        "held-out PSNR {:.2} -> {:.2} dB, SSIM {:.3} -> {:.3}, Gaussians {} -> {}, {:.1} steps/s, loss {:.4}",
        before.psnr,
        after.psnr,
        before.ssim,
        after.ssim,
        initial_gaussians,
        progress.gaussians,
        progress.steps_per_sec,
        progress.loss
    );
    assert_eq!(progress.step, 500);
    assert!(progress.loss.is_finite());
    assert!(
        after.psnr > 25.0 && after.psnr > before.psnr + 5.0,
        "held-out PSNR {:.2} (from {:.2}) is too low",
        after.psnr,
        before.psnr
    );
    assert!(after.ssim > before.ssim);
    // Densification ran (clones, splits and prunes change the count).
    assert_ne!(progress.gaussians, initial_gaussians);
}

/// Densification never grows the model past its Gaussian budget, and fills it: the candidates
/// it keeps are the highest-gradient ones, so a budget above the start is reached, not skipped.
/// A run longer than the steps its schedule is laid out over (`schedule_steps`) polishes after
/// them: every learning rate decays (`TrainSchedule::polish_factor_at`), so its Gaussians move far
/// less in those steps than the same run's do without the polish. Both runs are the same up to
/// step 20 and differ after it only in the polish (no densification, the coarse steps, the SH
/// ramp and the position decay given alike).
#[test]
fn a_run_past_its_schedule_polishes_what_it_laid_out() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let moved_after_step_20 = |schedule_steps: Option<u32>| {
        let config = TrainConfig {
            schedule_steps,
            coarse_until: Some(0),
            learning_rates: LearningRates {
                position_decay_steps: Some(20),
                ..LearningRates::default()
            },
            ..config(60)
        };
        let mut trainer = Trainer::new(&ctx, &scene, config, None).unwrap();
        trainer.run_until(20, |_| true).unwrap();
        let laid_out = trainer.model().unwrap();
        trainer.run(|_| true).unwrap();
        let end = trainer.model().unwrap();
        let colours: f32 = laid_out
            .sh_coefficients
            .iter()
            .zip(&end.sh_coefficients)
            .map(|(a, b)| (0..3).map(|c| (a[0][c] - b[0][c]).abs()).sum::<f32>())
            .sum();
        let opacities: f32 = laid_out
            .opacity_logits
            .iter()
            .zip(&end.opacity_logits)
            .map(|(a, b)| (a - b).abs())
            .sum();
        colours + opacities
    };
    let polished = moved_after_step_20(Some(20));
    let full_rate = moved_after_step_20(None);
    eprintln!("moved after step 20: polished {polished:.3}, at full rate {full_rate:.3}");
    assert!(full_rate > 0.0);
    assert!(
        polished < 0.4 * full_rate,
        "the polish moved the Gaussians {polished} against {full_rate} at full rate"
    );
}

#[test]
fn densification_stays_within_the_gaussian_budget() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let start = plain_initial_model(&scene, &config(300)).unwrap().len();
    let budget = start + 40;
    let budgeted = TrainConfig {
        gaussian_budget: Some(budget),
        ..config(300)
    };
    let mut trainer = Trainer::new(&ctx, &scene, budgeted, None).unwrap();
    assert_eq!(trainer.gaussian_budget(), budget);
    let mut largest = 0;
    trainer
        .run(|progress| {
            largest = largest.max(progress.gaussians);
            true
        })
        .unwrap();
    assert!(
        largest <= budget,
        "{largest} Gaussians against a budget of {budget}"
    );
    assert!(largest > start, "the budget left room, yet nothing grew");
    // Left out, the budget follows the training pixels (never below the start).
    let mut scene_sized = Trainer::new(&ctx, &scene, config(300), None).unwrap();
    let pixels: u64 = scene_sized
        .views()
        .train
        .iter()
        .map(|view| view.camera.pixel_count() as u64)
        .sum();
    assert_eq!(
        scene_sized.gaussian_budget(),
        segsplat_engine::train::budget::scene_gaussian_budget(pixels, start)
    );
    scene_sized.run_until(1, |_| true).unwrap();
}

/// Once every view has been trained on, a step allocates nothing and creates no bind group: the
/// kernels' parameters go into the context's uniform ring and their bind groups come from the
/// cache (issue 38, item 4). Counted, not timed.
#[test]
fn steady_steps_create_no_buffers_and_no_bind_groups() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let steady = TrainConfig {
        densify_from: Some(10_000),
        ..config(200)
    };
    let mut trainer = Trainer::new(&ctx, &scene, steady, None).unwrap();
    let views = trainer.views().train.len() as u32;
    // The coarse half, then two passes over the views at full resolution.
    let warm = 100 + 2 * views;
    trainer.run_until(warm, |_| true).unwrap();
    gpu_support::assert_steps_allocate_nothing(&ctx, &mut trainer, views);
}

/// The coarse steps (the first half by default) train on each view filtered down to half
/// resolution through the same camera at half the pixel grid, and the job ends as well trained as
/// one at full resolution throughout.
#[test]
fn coarse_steps_train_at_half_resolution_as_well_as_full() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let coarse = Trainer::new(&ctx, &scene, config(500), None).unwrap();
    assert_eq!(coarse.schedule().coarse_until, 250);
    assert_eq!(coarse.schedule().resolution_divisor_at(0), 2);
    for view in &coarse.views().train {
        let [half] = view.coarse.as_slice() else {
            panic!("{} coarse images, expected one", view.coarse.len());
        };
        assert_eq!(
            (half.divisor, half.camera.width, half.camera.height),
            (2, 32, 24)
        );
        // The filtered image keeps the full one's mean colour.
        let full: Vec<[f32; 4]> = ctx.read_vec(&view.target).unwrap();
        let reduced: Vec<[f32; 4]> = ctx.read_vec(&half.target).unwrap();
        assert_eq!(reduced.len(), 32 * 24);
        let mean = |pixels: &[[f32; 4]]| {
            pixels.iter().map(|p| p[0] + p[1] + p[2]).sum::<f32>() / pixels.len() as f32
        };
        assert!((mean(&full) - mean(&reduced)).abs() < 0.02);
    }
    assert!(
        coarse
            .views()
            .test
            .iter()
            .all(|view| view.coarse.is_empty())
    );
    let mut results = Vec::new();
    for coarse_until in [None, Some(0)] {
        let config = TrainConfig {
            coarse_until,
            ..config(500)
        };
        let mut trainer = Trainer::new(&ctx, &scene, config, None).unwrap();
        let progress = trainer.run(|_| true).unwrap();
        let report = trainer.evaluate().unwrap();
        eprintln!(
            "coarse_until {coarse_until:?}: held-out PSNR {:.2} dB, SSIM {:.3}, {} Gaussians",
            report.psnr, report.ssim, progress.gaussians
        );
        results.push(report.psnr);
    }
    assert!(
        results[0] > 25.0 && results[0] > results[1] - 1.0,
        "coarse then fine {:.2} dB against full resolution throughout {:.2} dB",
        results[0],
        results[1]
    );
}

/// The convergence stop (`stop_when_converged`): checks start at the floor (here the end of
/// densification), a fit that has not gained the rule's minimum over its window ends the run
/// there (the report, `end_step` and a checkpoint say so, and a resumed trainer stays ended),
/// and a rule that asks for no gain never ends a run whose fit keeps its best.
#[test]
fn the_convergence_stop_ends_a_run_when_the_fit_stops_gaining() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    // 28 training views: a check every pass (28 steps), a window of two passes.
    let rule = ConvergenceStop {
        min_gain_db: 1000.0,
        window_passes: 2,
        check_every_passes: 1,
        check_views: 2,
    };
    // Short: densification from step 100 to 150, the SH bands by 90, no coarse steps.
    let short = |steps| TrainConfig {
        densify_until: Some(150),
        sh_degree_interval: Some(30),
        coarse_until: Some(0),
        stop_when_converged: Some(rule),
        ..config(steps)
    };
    let stopping = short(300);
    let mut trainer = Trainer::new(&ctx, &scene, stopping, None).unwrap();
    assert_eq!(trainer.convergence_floor(), 150);
    let progress = trainer.run(|_| true).unwrap();
    // Checks at 150, 178 and 206; the window (56 steps) has a start from 206 on.
    assert_eq!((progress.step, progress.total_steps), (206, 206));
    let converged = trainer.converged_at().expect("the run converged");
    assert_eq!(converged.step, 206);
    assert_eq!(trainer.end_step(), 206);
    let checks: Vec<u32> = trainer.fit_checks().iter().map(|&(step, _)| step).collect();
    assert_eq!(checks, vec![150, 178, 206]);
    for &(step, psnr) in trainer.fit_checks() {
        assert!(
            psnr.is_finite() && psnr > 12.0,
            "fit {psnr} dB at step {step}"
        );
    }
    let saved = trainer.checkpoint().unwrap();
    let mut resumed = Trainer::resume(&ctx, &scene, &saved).unwrap();
    assert_eq!(resumed.end_step(), 206);
    assert_eq!(
        resumed.run(|_| true).unwrap().step,
        206,
        "a converged run stays ended"
    );

    // No gain asked: the best fit never falls below itself, so the run trains every step.
    let patient = TrainConfig {
        stop_when_converged: Some(ConvergenceStop {
            min_gain_db: 0.0,
            ..rule
        }),
        ..short(260)
    };
    let mut trainer = Trainer::new(&ctx, &scene, patient, None).unwrap();
    assert_eq!(trainer.run(|_| true).unwrap().step, 260);
    assert_eq!(trainer.converged_at(), None);
    assert_eq!(
        trainer.fit_checks().len(),
        4,
        "checks at 150, 178, 206 and 234"
    );
}

/// Views decode on every core, a batch at a time, and upload in capture order: loading them on
/// one thread and on three gives the same views in the same order, bit for bit, coarse images
/// included (the pool's size only changes which thread decodes which frame).
#[test]
fn views_load_the_same_on_one_thread_and_on_several() {
    use segsplat_engine::train::views::Views;
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let load = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let views = pool
            .install(|| Views::load(&ctx, &scene, Some(48), 8, 2))
            .unwrap();
        let read = |buffer: &wgpu::Buffer| ctx.read_buffer(buffer, buffer.size()).unwrap();
        let describe = |views: &[segsplat_engine::train::views::View]| {
            views
                .iter()
                .map(|view| {
                    let coarse: Vec<(u32, [u32; 2], Vec<u8>)> = view
                        .coarse
                        .iter()
                        .map(|c| {
                            (
                                c.divisor,
                                [c.camera.width, c.camera.height],
                                read(&c.target),
                            )
                        })
                        .collect();
                    (
                        view.frame_index,
                        [view.camera.width, view.camera.height],
                        read(&view.target),
                        view.target_rgb.clone(),
                        coarse,
                    )
                })
                .collect::<Vec<_>>()
        };
        (describe(&views.train), describe(&views.test))
    };
    let (one_train, one_test) = load(1);
    let (three_train, three_test) = load(3);
    assert_eq!(one_train.len(), 28, "32 frames, every 8th held out");
    assert_eq!(one_test.len(), 4);
    assert!(
        one_train.iter().all(|view| view.4.len() == 2),
        "two coarse levels"
    );
    let order: Vec<usize> = one_train.iter().map(|view| view.0).collect();
    assert!(order.windows(2).all(|pair| pair[0] < pair[1]), "{order:?}");
    assert!(one_train == three_train, "training views differ");
    assert!(one_test == three_test, "held-out views differ");
}

/// A model that needs far more tile intersections at its first step than the renderer's initial
/// guess (8 a Gaussian, at least 65,536) trains no step on clamped renders: the trainer fits the
/// capacity to its first step's render before it (`Trainer::size_intersections`), where the
/// first read of the renders' peak would come 25 steps in. Passes timed before the first step
/// (`Trainer::time_passes`, as bench does) are timed on whole renders.
#[test]
fn the_first_steps_render_every_intersection() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let cfg = TrainConfig {
        coarse_until: Some(0),
        densify_from: Some(10_000),
        ..config(30)
    };
    // 6000 wide Gaussians at the middle of the scene, where every camera looks: each covers all
    // 12 tiles of a view, so a step needs 72,000 intersections (the initial guess: 65,536).
    let mut wide = segsplat_engine::GaussianModel::default();
    for index in 0..6000 {
        let mean = [index as f32 * 1e-5, 0.0, 0.0];
        wide.push_simple(
            mean,
            [8.0f32.ln(); 3],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            [0.5; 3],
            [0; 3],
        );
    }
    // bench times a trainer's render passes before its first step, at the capacity not yet
    // fitted: those renders are timed again once it fits, and train nothing either way.
    assert_trains_unclamped(&ctx, &scene, cfg, wide, |trainer| {
        trainer.time_passes(1).unwrap();
        assert_eq!(trainer.clamped_renders(), 0, "timed renders counted");
    });
}

/// Footprints that widen fast in the first steps (Gaussians growing and turning opaque to cover
/// a background the render lacks: 45k intersections at the first step, 78k by step 10) keep
/// their renders whole: the trainer reads the renders' peak every step of its first hundred.
/// Read every 25 steps, as after them, 44 of these 50 steps trained on clamped renders.
#[test]
fn footprints_growing_in_the_first_steps_are_not_clamped() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let spec = segsplat_scene::synthetic::SyntheticSpec {
        frame_count: 16,
        width: 128,
        height: 96,
        ..Default::default()
    };
    segsplat_scene::synthetic::write_colmap(
        dir.path(),
        &spec,
        segsplat_scene::colmap::ColmapEncoding::Text,
    )
    .unwrap();
    let scene =
        segsplat_scene::load_scene(dir.path(), &segsplat_scene::LoadOptions::default()).unwrap();
    // A black render background against the images' grey one: Gaussians of that grey gain by
    // growing and turning opaque until they cover the frame.
    let cfg = TrainConfig {
        coarse_until: Some(0),
        densify_from: Some(10_000),
        background: [0.0; 3],
        ..config(50)
    };
    let grey = segsplat_scene::synthetic::SYNTHETIC_BACKGROUND.map(|c| c as f32 / 255.0);
    // Faint blobs filling a ball that every view frames, each about 16 px across at first.
    let mut faint = segsplat_engine::GaussianModel::default();
    let count = 8000;
    for index in 0..count {
        let turn = index as f32 * 2.399_963;
        let height = 1.0 - 2.0 * (index as f32 + 0.5) / count as f32;
        let ring = (1.0 - height * height).sqrt();
        let radius = 1.5 * ((index * 7919 % count) as f32 / count as f32).cbrt();
        let mean = [
            radius * ring * turn.cos(),
            radius * height,
            radius * ring * turn.sin(),
        ];
        faint.push_simple(
            mean,
            [0.6f32.ln(); 3],
            [1.0, 0.0, 0.0, 0.0],
            -5.3,
            grey,
            [0; 3],
        );
    }
    assert_trains_unclamped(&ctx, &scene, cfg, faint, |_| {});
}

/// Trains `model` on `scene` for all of `cfg`'s steps, after `before` has had the trainer, and
/// checks that no step used a clamped render.
fn assert_trains_unclamped(
    ctx: &segsplat_gpu::GpuContext,
    scene: &segsplat_scene::Scene,
    cfg: TrainConfig,
    model: segsplat_engine::GaussianModel,
    before: impl FnOnce(&mut Trainer),
) {
    let steps = cfg.steps;
    let mut trainer = Trainer::new(ctx, scene, cfg, Some(model)).unwrap();
    before(&mut trainer);
    let progress = trainer.run(|_| true).unwrap();
    assert_eq!(progress.step, steps);
    assert_eq!(
        trainer.clamped_renders(),
        0,
        "steps trained on clamped renders"
    );
}
