//! Propagation on the synthetic moving-discs sequence with stand-in segmenters (see
//! `test_support`): identities, new and leaving objects, duplicates, batching, ORR and Dup.

use std::collections::{HashMap, HashSet};

use super::test_support::{
    DISCS, DUPLICATE_ID, FRAMES, PROMPTS_PER_CALL, RegionOracle, TILE_IDS, first_frame,
    frame_image, generator, options, run, truth_ids,
};
use super::*;

/// Truth pixels below which a disc (entering or leaving) is not measured.
const MIN_MEASURED_AREA: usize = 30;

/// Per frame where truth object `truth_id` shows with enough pixels: the predicted id covering
/// most of it and their IoU.
fn matches(propagation: &Propagation, level: usize, truth_id: u32) -> Vec<(usize, u32, f64)> {
    let mut found = Vec::new();
    for (frame, predicted) in propagation.frames.iter().enumerate() {
        let truth = &truth_ids(frame)[level];
        let mut overlap: HashMap<u32, usize> = HashMap::new();
        let mut truth_area = 0;
        for (&t, &p) in truth.iter().zip(&predicted[level]) {
            if t == truth_id {
                truth_area += 1;
                *overlap.entry(p).or_default() += 1;
            }
        }
        if truth_area < MIN_MEASURED_AREA {
            continue;
        }
        let Some((&id, &intersection)) = overlap
            .iter()
            .filter(|(id, _)| **id != 0)
            .max_by_key(|(id, count)| (**count, std::cmp::Reverse(**id)))
        else {
            found.push((frame, 0, 0.0));
            continue;
        };
        let predicted_area = predicted[level].iter().filter(|&&p| p == id).count();
        let iou = intersection as f64 / (truth_area + predicted_area - intersection) as f64;
        found.push((frame, id, iou));
    }
    found
}

#[test]
fn each_object_keeps_one_id_with_a_high_iou_in_every_frame() {
    let (propagation, _) = run();
    assert_eq!(propagation.frames.len(), FRAMES);
    for level in 0..3 {
        let mut objects: Vec<u32> = (1..=DISCS.len() as u32).collect();
        if level == 2 {
            objects.extend(TILE_IDS);
        }
        let mut ids_taken = HashSet::new();
        let mut worst = 1.0f64;
        for truth_id in objects {
            let found = matches(&propagation, level, truth_id);
            // The entering disc is an object from the check that finds it (frame 20) on.
            let tracked: Vec<_> = found
                .iter()
                .filter(|(frame, _, _)| truth_id != 4 || *frame >= 20)
                .collect();
            assert!(!tracked.is_empty());
            let id = tracked[0].1;
            assert!(id != 0, "level {level}: object {truth_id} found");
            for (frame, found_id, iou) in &tracked {
                assert_eq!(
                    *found_id, id,
                    "level {level} object {truth_id} frame {frame}"
                );
                assert!(
                    *iou > 0.95,
                    "level {level} object {truth_id} frame {frame}: {iou}"
                );
                worst = worst.min(*iou);
            }
            assert!(
                ids_taken.insert(id),
                "level {level}: id {id} on two objects"
            );
        }
        println!("level {level}: worst per-frame IoU {worst:.4}");
    }
}

#[test]
fn an_entering_disc_is_a_new_object_at_the_next_check() {
    let (propagation, _) = run();
    let checks = &propagation.report.checks;
    println!("{checks:#?}");
    assert_eq!(
        checks
            .iter()
            .map(|check| check.frame_index)
            .collect::<Vec<_>>(),
        vec![10, 20]
    );
    // Frame 10: the green disc left, so the small and middle levels lost coverage; nothing new.
    assert!(checks[0].detection_ran);
    assert_eq!(checks[0].new_objects, [0; 3]);
    // Frame 20: the yellow disc (in since frame 12) uncovers the large level's tiles.
    assert!(checks[1].detection_ran);
    assert_eq!(checks[1].new_objects, [1; 3]);
    let first_max = [DUPLICATE_ID, 3, 11];
    for (level, first_max) in first_max.into_iter().enumerate() {
        let found = matches(&propagation, level, 4);
        let before: Vec<_> = found.iter().filter(|(frame, _, _)| *frame < 20).collect();
        assert!(before.iter().all(|(_, id, _)| *id == 0), "not before 20");
        let after: Vec<_> = found.iter().filter(|(frame, _, _)| *frame >= 20).collect();
        assert_eq!(after.len(), 10);
        assert_eq!(after[0].2, 1.0);
        assert_eq!(after[0].1, first_max + 1, "the next unused id");
    }
}

#[test]
fn a_leaving_disc_ends_and_its_id_is_not_reused() {
    let (propagation, _) = run();
    assert_eq!(
        propagation.report.ended,
        [1, 1, 1],
        "the green disc, per level"
    );
    assert!(
        propagation
            .report
            .lost_frames
            .iter()
            .all(|&lost| lost >= 10)
    );
    for (frame, ids) in propagation.frames.iter().enumerate().skip(9) {
        for (level, level_ids) in ids.iter().enumerate() {
            assert!(
                !level_ids.contains(&3),
                "frame {frame} level {level}: the green disc's id"
            );
        }
    }
}

#[test]
fn two_tracks_of_one_disc_become_one() {
    let (propagation, _) = run();
    let drops = &propagation.report.duplicates;
    assert_eq!(drops.len(), 1, "{drops:?}");
    assert_eq!(drops[0].level, Level::Small);
    assert_eq!((drops[0].dropped, drops[0].kept), (DUPLICATE_ID, 1));
    assert_eq!(drops[0].frame_index, 10);
    assert!(drops[0].iou > 0.99);
    assert!(
        propagation
            .frames
            .iter()
            .all(|frame| !frame[0].contains(&DUPLICATE_ID))
    );
    // Frame 0's two halves are one object now.
    let found = matches(&propagation, 0, 1);
    assert_eq!(found[0], (0, 1, 1.0));
    assert_eq!(propagation.report.objects_per_level, [4, 4, 6]);
}

#[test]
fn prompts_are_batched_and_carry_the_previous_answer() {
    let (propagation, oracle) = run();
    assert_eq!(oracle.largest_call, PROMPTS_PER_CALL);
    assert_eq!(oracle.prompts as u64, propagation.report.prompts);
    assert!(propagation.report.segmenter_calls >= propagation.report.prompts / 4);
    // Every frame but the first after frame 0 and after each re-anchoring carries priors.
    assert!(oracle.prompts_with_prior > oracle.prompts / 2);
    assert!(oracle.prompts_with_prior < oracle.prompts);
}

#[test]
fn frames_of_another_size_and_load_failures_are_errors() {
    let mut oracle = RegionOracle::default();
    let wrong_size = propagate_masks(
        3,
        |_| Ok::<_, std::convert::Infallible>(image::RgbImage::new(64, 48)),
        first_frame(),
        &mut oracle,
        &mut generator(),
        &options(),
    );
    assert!(matches!(
        wrong_size,
        Err(PropagationError::FrameSize { frame_index: 1, .. })
    ));
    let failing = propagate_masks(
        3,
        |frame| {
            if frame == 2 {
                Err("disk gone")
            } else {
                Ok(frame_image(frame))
            }
        },
        first_frame(),
        &mut oracle,
        &mut generator(),
        &options(),
    );
    assert!(matches!(
        failing,
        Err(PropagationError::LoadFrame { frame_index: 2, .. })
    ));
    let invalid = PropagationOptions {
        stride: 0,
        ..options()
    };
    assert!(matches!(
        propagate_masks(
            3,
            |frame| Ok::<_, std::convert::Infallible>(frame_image(frame)),
            first_frame(),
            &mut oracle,
            &mut generator(),
            &invalid,
        ),
        Err(PropagationError::InvalidOptions {
            field: "stride",
            ..
        })
    ));
}

#[test]
fn one_frame_is_the_first_frame() {
    let mut oracle = RegionOracle::default();
    let propagation = propagate_masks(
        1,
        |_| Err::<image::RgbImage, _>("never loaded"),
        first_frame(),
        &mut oracle,
        &mut generator(),
        &options(),
    )
    .expect("nothing to load");
    assert_eq!(propagation.frames, vec![first_frame().ids]);
    assert_eq!(oracle.prompts, 0);
}
