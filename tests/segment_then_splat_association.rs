//! Stage 1 for posed static scenes without user masks, on the synthetic three-sphere scene
//! (32 ring views at 96x72, exact masks at three levels, COLMAP points with tracks): per-view
//! masks get one id per object across views from the sparse points they share.
//!
//! - The scene's own masks with ids scrambled in every view must come back as exactly one
//!   object per sphere group per level (ORR 1, Dup 0), with tracks and with projected points.
//! - The classical generator must reach the ORR/Dup stated below at the small level.
//! - Trained end to end from classical masks, each true object's best predicted object (any
//!   level, the issue's `--oracle` selection) must match its held-out full silhouette.

mod gpu_support;
mod segment_then_splat_support;

use segment_then_splat_support::{config, full_truth, gpu, iou, mean, synthetic_scene};
use segsplat_engine::ObjectFilter;
use segsplat_engine::render::Renderer;
use std::ops::ControlFlow;

use segsplat_method::segment_then_splat::association::{
    AssociationError, AssociationOptions, AssociationReport, associate_frame_masks, frame_rgb8,
    generated_view_masks,
};
use segsplat_method::segment_then_splat::frame_masks::generate_frame_masks;
use segsplat_method::segment_then_splat::objects::{full_mask, render_layer};
use segsplat_method::segment_then_splat::track_metrics::object_recall_and_duplicates;
use segsplat_method::segment_then_splat::training::{
    SegmentedTrainingOptions, segmented_trainer_from_generated_masks, training_frames,
};
use segsplat_method::segment_then_splat::view_masks::ViewMaskSet;
use segsplat_scene::{Level, Scene};
use segsplat_vision::segment::{ClassicalConfig, MaskGenerator, SegmentError, user_frame_masks};

/// Objects per level (small, middle, large) in the synthetic scene.
const TRUE_OBJECTS: [usize; 3] = [3, 2, 1];
/// The (tuned) classical generator at the small level. Measured: ORR 2/3, Dup 2 (the shaded
/// spheres still split into regions the one-object-per-view rule keeps apart); middle and large
/// ORR 1, Dup 0.
const MIN_CLASSICAL_SMALL_ORR: f64 = 0.6;
const MAX_CLASSICAL_SMALL_DUP: usize = 2;
const MIN_CLASSICAL_COARSE_ORR: f64 = 0.99;
/// Held-out full mIoU of the oracle-selected objects trained from classical masks (measured 0.91).
const MIN_CLASSICAL_ORACLE_MIOU: f64 = 0.8;

/// The classical generator tuned for these small flat-shaded renders: FH scales ten times the
/// defaults (which, scaled down to 96x72, split each shaded sphere into several regions).
fn classical_generator() -> MaskGenerator {
    MaskGenerator::Classical(ClassicalConfig {
        scale_per_level: [1000.0, 4000.0, 16000.0],
        ..ClassicalConfig::default()
    })
}

/// Associates the scene's own masks after scrambling them in every view: each level's masks
/// rotated and (in odd views) reversed, so local order says nothing, and their source ids
/// replaced by view-specific ones.
fn associate_scrambled_user_masks(
    scene: &Scene,
    frames: &[usize],
) -> (ViewMaskSet, AssociationReport) {
    let (masks, report) = associate_frame_masks(
        scene,
        frames,
        None,
        &AssociationOptions::default(),
        |frame_index| {
            let mut frame = user_frame_masks(scene, frame_index)
                .map_err(|error| AssociationError::Segment(SegmentError::User(error)))?;
            for level in &mut frame.levels {
                if !level.is_empty() {
                    let shift = frame_index % level.len();
                    level.rotate_left(shift);
                }
                if frame_index % 2 == 1 {
                    level.reverse();
                }
                for (index, scored) in level.iter_mut().enumerate() {
                    scored.instance_id = Some(1000 + 7 * frame_index as u32 + index as u32);
                }
            }
            Ok(frame)
        },
    )
    .unwrap();
    eprintln!("{report:?}");
    (masks, report)
}

fn assert_exact_recovery(predicted: &ViewMaskSet, truth: &ViewMaskSet) {
    for level in Level::ALL {
        let quality = object_recall_and_duplicates(predicted, truth, level, 0.5).unwrap();
        eprintln!("{level:?}: {quality:?}");
        assert_eq!(quality.truth_objects, TRUE_OBJECTS[level.index()]);
        assert_eq!(quality.object_recall_rate, 1.0, "{level:?}");
        assert_eq!(quality.duplicated_objects, 0, "{level:?}");
        // Ids are 1..N.
        let mut ids: Vec<u32> = predicted
            .views
            .iter()
            .flat_map(|view| view.objects_at(level))
            .collect();
        ids.sort_unstable();
        ids.dedup();
        let expected: Vec<u32> = (1..=TRUE_OBJECTS[level.index()] as u32).collect();
        assert_eq!(ids, expected, "{level:?}");
    }
}

#[test]
fn scrambled_user_masks_regain_one_id_per_object_by_tracks_and_by_projection() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = synthetic_scene(dir.path(), |_| ());
    let frames = training_frames(&scene, &config());
    let truth = ViewMaskSet::from_user_masks(&scene, &frames, None).unwrap();

    let (by_tracks, report) = associate_scrambled_user_masks(&scene, &frames);
    for (level, expected) in Level::ALL.into_iter().zip(TRUE_OBJECTS) {
        assert_eq!(report.levels[level.index()].objects, expected, "{level:?}");
        assert_eq!(report.levels[level.index()].refused_merges, 0, "{level:?}");
    }
    assert_exact_recovery(&by_tracks, &truth);

    // Without tracks every point is projected into every view instead (hidden ones filtered
    // by depth against each mask's front).
    let points = scene.points.as_mut().unwrap();
    points.tracks.iter_mut().for_each(Vec::clear);
    let (by_projection, _) = associate_scrambled_user_masks(&scene, &frames);
    assert_exact_recovery(&by_projection, &truth);
}

#[test]
fn classical_masks_associate_with_stated_recall_and_no_duplicates() {
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path(), |_| ());
    let frames = training_frames(&scene, &config());
    let truth = ViewMaskSet::from_user_masks(&scene, &frames, None).unwrap();
    let mut generator = classical_generator();
    let (masks, report) = generated_view_masks(
        &scene,
        &frames,
        &mut generator,
        None,
        &AssociationOptions::default(),
    )
    .unwrap();
    eprintln!("{report:#?}");
    for level in Level::ALL {
        let quality = object_recall_and_duplicates(&masks, &truth, level, 0.5).unwrap();
        eprintln!("classical {level:?}: {quality:?}");
        if level != Level::Small {
            assert!(
                quality.object_recall_rate >= MIN_CLASSICAL_COARSE_ORR,
                "{level:?}: {quality:?}"
            );
        }
    }
    let small = object_recall_and_duplicates(&masks, &truth, Level::Small, 0.5).unwrap();
    assert!(
        small.object_recall_rate >= MIN_CLASSICAL_SMALL_ORR,
        "{small:?}"
    );
    assert!(
        small.duplicated_objects <= MAX_CLASSICAL_SMALL_DUP,
        "{small:?}"
    );
}

/// The classical generator segments the views on every core at once
/// (`frame_masks::generate_frame_masks`): the same masks as made one view at a time, progress
/// counted once per view, and a stop heard after the views then in flight.
#[test]
fn views_segmented_at_once_are_the_views_segmented_one_by_one() {
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path(), |_| ());
    let frames = training_frames(&scene, &config());
    let mut generator = classical_generator();
    let mut heard = Vec::new();
    let masks = generate_frame_masks(&scene, &frames, &mut generator, None, |done| {
        heard.push(done);
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(heard, (0..=frames.len()).collect::<Vec<_>>());
    assert_eq!(masks.len(), frames.len());
    for &frame_index in &frames {
        let image = frame_rgb8(&scene, frame_index, None).unwrap();
        let one_by_one = generator.generate(&image, frame_index).unwrap();
        assert!(masks[&frame_index] == one_by_one, "frame {frame_index}");
    }

    let stopped = generate_frame_masks(&scene, &frames, &mut generator, None, |done| {
        if done >= 2 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    });
    match stopped {
        Err(AssociationError::Stopped { views_done }) => {
            // The views already started finish first: how many depends on the threads.
            assert!((2..=frames.len()).contains(&views_done), "{views_done}")
        }
        other => panic!("expected a stop, got {:?}", other.map(|masks| masks.len())),
    }
}

#[test]
fn trained_from_classical_masks_oracle_objects_match_held_out_truth() {
    let Some(ctx) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path(), |_| ());
    let mut generator = classical_generator();
    let (mut trainer, report) = segmented_trainer_from_generated_masks(
        &ctx,
        &scene,
        config(),
        &mut generator,
        &SegmentedTrainingOptions::default(),
        &AssociationOptions::default(),
    )
    .unwrap();
    eprintln!("{report:?}");
    let progress = trainer.run(|_| true).unwrap();
    eprintln!("trained: {progress:?}");

    // Every predicted object's full mask in every held-out view.
    let mut renderer = Renderer::new(&ctx).unwrap();
    let test_views = &trainer.views().test;
    let predicted: Vec<(Level, u32)> = Level::ALL
        .into_iter()
        .flat_map(|level| {
            let count = report.levels[level.index()].objects as u32;
            (1..=count).map(move |id| (level, id))
        })
        .collect();
    let rendered: Vec<Vec<Vec<bool>>> = predicted
        .iter()
        .map(|&(level, id)| {
            test_views
                .iter()
                .map(|view| {
                    let filter = ObjectFilter::Object { level, id };
                    let layer = render_layer(
                        &ctx,
                        &mut renderer,
                        trainer.gaussians(),
                        &view.camera,
                        filter,
                    )
                    .unwrap();
                    full_mask(&layer)
                })
                .collect()
        })
        .collect();

    // Oracle: each true object gets the one predicted object (any level) with the best mean
    // held-out IoU; mIoU is then the paper's (per view over the objects, then over views).
    let mut per_view_scores = vec![Vec::new(); test_views.len()];
    for level in Level::ALL {
        for object in 1..=TRUE_OBJECTS[level.index()] as u32 {
            let truths: Vec<Vec<bool>> = test_views
                .iter()
                .map(|view| full_truth(&scene, view.frame_index, level, object))
                .collect();
            let scores_of = |masks: &Vec<Vec<bool>>| -> Vec<f64> {
                masks.iter().zip(&truths).map(|(m, t)| iou(m, t)).collect()
            };
            let best = rendered
                .iter()
                .map(scores_of)
                .max_by(|a, b| mean(a).total_cmp(&mean(b)))
                .unwrap_or_else(|| vec![0.0; test_views.len()]);
            eprintln!("{level:?} object {object}: best IoUs {best:.3?}");
            for (scores, score) in per_view_scores.iter_mut().zip(best) {
                scores.push(score);
            }
        }
    }
    let miou = mean(&per_view_scores.iter().map(|s| mean(s)).collect::<Vec<_>>());
    eprintln!("held-out oracle full mIoU from classical masks: {miou:.4}");
    assert!(miou >= MIN_CLASSICAL_ORACLE_MIOU, "oracle mIoU {miou:.4}");
}
