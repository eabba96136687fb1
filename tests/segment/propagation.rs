//! Mask propagation through the tiny ONNX SAM stand-in (tests/fixtures/models/tiny): frame-0
//! discs are tracked by re-prompting the decoder with their previous masks, and a disc that
//! appears is found by automatic masks at a check after another disc left the frame.
//!
//! The stand-in reads only a prompt's first point (the deepest interior point of the previous
//! mask) and answers the region of that point's colour within a radius; it ignores the box and
//! takes the mask prior as a small bias. So this checks the plumbing (prompts, batching, the
//! single-mask channel, priors fed back, answers at full resolution) on a model that does follow
//! objects, not SAM's quality.

use crate::models_support;

use models_support::{discs_image, mask_iou};
use segsplat_vision::models::sam::{SamModel, SamPredictor};
use segsplat_vision::segment::propagation::{FirstFrameMasks, PropagationOptions, propagate_masks};
use segsplat_vision::segment::{AutomaticConfig, MaskGenerator};

const WIDTH: u32 = 160;
const HEIGHT: u32 = 120;
const FRAMES: usize = 12;

/// `(centre x, centre y, radius, colour, velocity, first frame)`.
type Disc = (f32, f32, f32, [u8; 3], [f32; 2], usize);

const DISCS: [Disc; 5] = [
    (40.0, 40.0, 16.0, [220, 30, 30], [2.0, 1.0], 0),
    (110.0, 45.0, 17.0, [30, 40, 210], [1.0, 1.0], 0),
    (80.0, 90.0, 15.0, [235, 220, 30], [1.0, -1.0], 0),
    // Leaves on the right by frame 4, so the next check looks for new objects ...
    (152.0, 105.0, 12.0, [200, 60, 220], [6.0, 0.0], 0),
    // ... and finds this one, which appears at frame 3.
    (30.0, 95.0, 12.0, [30, 200, 60], [0.0, 0.0], 3),
];
const LEAVING: usize = 3;
const APPEARING: usize = 4;

/// Frame `frame`'s image and, per disc, its truth pixels (`None` before it appears).
fn frame(frame: usize) -> (image::RgbImage, Vec<Option<Vec<bool>>>) {
    let shown: Vec<usize> = (0..DISCS.len())
        .filter(|&index| frame >= DISCS[index].5)
        .collect();
    let discs: Vec<(f32, f32, f32, [u8; 3])> = shown
        .iter()
        .map(|&index| {
            let (x, y, radius, colour, [vx, vy], from) = DISCS[index];
            let t = (frame - from) as f32;
            (x + vx * t, y + vy * t, radius, colour)
        })
        .collect();
    let (image, truths) = discs_image(WIDTH, HEIGHT, &discs);
    let mut per_disc = vec![None; DISCS.len()];
    for (index, truth) in shown.into_iter().zip(truths) {
        per_disc[index] = Some(truth);
    }
    (image, per_disc)
}

#[test]
fn discs_are_tracked_and_a_new_one_found_through_the_onnx_stand_in() {
    let Some(store) = models_support::tiny_store() else {
        return;
    };
    let predictor = SamPredictor::new(SamModel::new(&store).unwrap()).with_chunk(4);
    let (_, truths) = frame(0);
    let mut ids = vec![0u32; (WIDTH * HEIGHT) as usize];
    for (index, truth) in truths.iter().enumerate() {
        for (id, &inside) in ids.iter_mut().zip(truth.iter().flatten()) {
            if inside {
                *id = index as u32 + 1;
            }
        }
    }
    let first = FirstFrameMasks {
        width: WIDTH,
        height: HEIGHT,
        ids: [ids.clone(), ids.clone(), ids],
    };
    let mut generator = MaskGenerator::Automatic {
        segmenter: Box::new(predictor.clone().with_chunk(16)),
        config: AutomaticConfig {
            points_per_side: 8,
            points_per_batch: 16,
            ..AutomaticConfig::default()
        },
    };
    let options = PropagationOptions {
        stride: 5,
        new_object_min_area_at_full_res: 100.0,
        prompts_per_call: 6,
        ..PropagationOptions::default()
    };
    let mut segmenter = predictor;
    let propagation = propagate_masks(
        FRAMES,
        |index| Ok::<_, std::convert::Infallible>(frame(index).0),
        first,
        &mut segmenter,
        &mut generator,
        &options,
    )
    .unwrap();
    println!("{:#?}", propagation.report);
    assert_eq!(propagation.frames.len(), FRAMES);

    // The three discs that stay keep their frame-0 id at every level.
    let mut worst = 1.0f64;
    for (index, frame_ids) in propagation.frames.iter().enumerate() {
        let (_, truths) = frame(index);
        for (level, level_ids) in frame_ids.iter().enumerate() {
            for (disc, truth) in truths.iter().take(3).enumerate() {
                let predicted: Vec<bool> =
                    level_ids.iter().map(|&id| id == disc as u32 + 1).collect();
                let truth = truth.as_ref().unwrap();
                let iou = mask_iou(&predicted, truth);
                assert!(
                    iou > 0.9,
                    "frame {index} level {level} disc {disc}: IoU {iou}"
                );
                worst = worst.min(iou);
            }
        }
    }
    println!("tracked discs: worst per-frame IoU {worst:.3}");
    let report = &propagation.report;
    assert!(
        report.lost_frames.iter().all(|&lost| lost > 0),
        "the disc that left"
    );
    assert!(report.segmenter_calls > 0 && report.prompts >= 4 * 3 * (FRAMES as u64 - 1));

    // Frame 5's check looks (the leaving disc uncovered pixels) and the appeared disc becomes an
    // object of the large level, whose stand-in answer is the whole disc; it keeps that id.
    let check = &report.checks[0];
    assert_eq!(check.frame_index, 5);
    assert!(check.detection_ran);
    let large = 2;
    let mut appeared_id = None;
    for index in 5..FRAMES {
        let (_, truths) = frame(index);
        let truth = truths[APPEARING].as_ref().unwrap();
        let level_ids = &propagation.frames[index][large];
        let mut counts = std::collections::BTreeMap::new();
        for (&id, _) in level_ids.iter().zip(truth).filter(|(_, inside)| **inside) {
            *counts.entry(id).or_insert(0) += 1;
        }
        let (&id, _) = counts.iter().max_by_key(|(_, count)| **count).unwrap();
        // Frame 0 had four discs (ids 1-4); new objects take the ids after them.
        assert!(id > 4, "frame {index}: a new id, got {id}");
        assert_eq!(*appeared_id.get_or_insert(id), id, "frame {index}");
        let predicted: Vec<bool> = level_ids.iter().map(|&other| other == id).collect();
        let iou = mask_iou(&predicted, truth);
        assert!(iou > 0.9, "frame {index}: appeared disc IoU {iou}");
        worst = worst.min(iou);
    }
    println!("with the appeared disc: worst per-frame IoU {worst:.3}");
    // The disc that left no longer shows.
    for frame_ids in &propagation.frames[4..] {
        assert!(
            frame_ids
                .iter()
                .all(|ids| !ids.contains(&(LEAVING as u32 + 1)))
        );
    }
}
