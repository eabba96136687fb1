//! The trainer's object loss on batched object renders (every slot's image and loss gradient in
//! one buffer, the loss reading and writing its slot in place) against the reference path that
//! renders each object separately: the same objects sampled from the same state must give the
//! same object loss, step after step. `object_batch_gpu.rs` checks the renders and gradients
//! below the loss.

mod gpu_support;
mod segment_then_splat_support;

use segment_then_splat_support::{config, gpu, synthetic_scene};
use segsplat_engine::train::{ObjectLossConfig, TrainConfig};
use segsplat_method::segment_then_splat::training::{
    SegmentedTrainingOptions, segmented_trainer_from_user_masks,
};

/// Relative difference allowed between the two paths' object losses: float atomics sum the
/// gradients in a different order, so the models drift apart by rounding after the first step.
const TOLERANCE: f32 = 1e-3;

#[test]
fn batched_object_losses_match_separate_renders() {
    let Some(ctx) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path(), |_| {});
    // Every level from the first step, three objects each: slots overlap and occlude.
    let config = TrainConfig {
        object_loss: Some(ObjectLossConfig {
            objects_per_level: 3,
            middle_from: 0.0,
            large_from: 0.0,
            ..Default::default()
        }),
        ..config()
    };
    let options = SegmentedTrainingOptions::default();
    let mut batched =
        segmented_trainer_from_user_masks(&ctx, &scene, config.clone(), &options).unwrap();
    let mut separate = segmented_trainer_from_user_masks(&ctx, &scene, config, &options).unwrap();
    separate.set_separate_object_renders(true);
    for step in 1..=5 {
        batched.train_step().unwrap();
        separate.train_step().unwrap();
        let (a, b) = (
            batched.progress().unwrap().object_loss,
            separate.progress().unwrap().object_loss,
        );
        eprintln!("step {step}: object loss batched {a:.6}, separate {b:.6}");
        assert!(a > 0.0, "step {step}: no object loss");
        assert!(
            (a - b).abs() <= TOLERANCE * b.abs(),
            "step {step}: object loss batched {a} against separate {b}"
        );
    }
}

/// `fade_from_step`: the object loss keeps its weight up to that step, then falls to 0 over as
/// many steps again, on both paths (the loss values are weighted, as the gradients are).
#[test]
fn the_object_loss_fades_to_nothing_after_its_fade() {
    let Some(ctx) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path(), |_| {});
    let config = TrainConfig {
        object_loss: Some(ObjectLossConfig {
            objects_per_level: 1,
            middle_from: 0.0,
            large_from: 0.0,
            fade_from_step: Some(2),
            ..Default::default()
        }),
        ..config()
    };
    let options = SegmentedTrainingOptions::default();
    for separate_renders in [false, true] {
        let mut trainer =
            segmented_trainer_from_user_masks(&ctx, &scene, config.clone(), &options).unwrap();
        trainer.set_separate_object_renders(separate_renders);
        let mut losses = Vec::new();
        for _ in 0..6 {
            trainer.train_step().unwrap();
            losses.push(trainer.progress().unwrap().object_loss);
        }
        // Steps 0-2 at the full weight, step 3 at half, from step 4 none.
        assert!(losses[..3].iter().all(|&loss| loss > 0.0), "{losses:?}");
        assert!(losses[3] > 0.0, "{losses:?}");
        assert_eq!(&losses[4..], &[0.0, 0.0], "{losses:?}");
    }
}
