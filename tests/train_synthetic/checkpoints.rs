//! Checkpoints restore the trainer's state exactly, and the snapshot a job writes beside the step
//! loop is the blocking checkpoint.

use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::train::{Trainer, TrainerMeta};

use crate::gpu_support::{self, new_gpu_context};
use crate::support::{config, synthetic_scene};

#[test]
fn checkpoint_restores_state_exactly() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let mut trainer = Trainer::new(&ctx, &scene, config(150), None).unwrap();
    trainer.run(|progress| progress.step < 120).unwrap();
    let step = trainer.step();
    assert!((120..150).contains(&step), "stopped at {step}");
    let saved = trainer.checkpoint().unwrap();
    let path = dir.path().join("train.ckpt");
    saved.save(&path).unwrap();
    let loaded = Checkpoint::<TrainerMeta>::load(&path).unwrap();
    let resumed = Trainer::resume(&ctx, &scene, &loaded).unwrap();
    assert_eq!(resumed.step(), step);
    let again = resumed.checkpoint().unwrap();
    assert_eq!(again.sections, saved.sections, "state differs after resume");
    assert_eq!(
        serde_json::to_value(&again.meta).unwrap(),
        serde_json::to_value(&saved.meta).unwrap()
    );
    // And it keeps training to the configured end.
    let mut resumed = resumed;
    let progress = resumed.run(|_| true).unwrap();
    assert_eq!(progress.step, 150);
}

/// A job's checkpoint, GPU copies of the state read back on the writer's thread while the trainer
/// goes on, is the blocking checkpoint's bit for bit, and taking it reads nothing back and waits
/// for nothing on the step loop's thread (issue 38, item 4).
#[test]
fn checkpoint_snapshot_is_the_blocking_checkpoint() {
    let Some(ctx) = new_gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = synthetic_scene(dir.path());
    let mut trainer = Trainer::new(&ctx, &scene, config(150), None).unwrap();
    // Past the first densification, so the moments and statistics are not all zero.
    trainer.run_until(110, |_| true).unwrap();
    gpu_support::assert_snapshot_equals_checkpoint(&ctx, &mut trainer, 5);
}
