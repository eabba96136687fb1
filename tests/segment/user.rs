//! User-provided instance masks through `MaskGenerator::User`: the scene loader's masks become
//! per-level `ScoredMask`s that keep their ids, with the loader's level fallback.

use std::sync::Arc;

use image::RgbImage;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{SyntheticSpec, write_colmap};
use segsplat_scene::{Level, LoadOptions, load_instance_mask, load_scene};
use segsplat_vision::segment::{MaskGenerator, SegmentError, UserMaskError};

fn spec(with_masks: Option<Vec<Level>>) -> SyntheticSpec {
    SyntheticSpec {
        frame_count: 2,
        width: 48,
        height: 36,
        with_masks,
        ..SyntheticSpec::default()
    }
}

#[test]
fn user_masks_become_certain_masks_per_level_with_their_ids() {
    let dir = tempfile::tempdir().expect("temp dir");
    write_colmap(
        dir.path(),
        &spec(Some(vec![Level::Small, Level::Large])),
        ColmapEncoding::Text,
    )
    .expect("writes dataset");
    let scene = Arc::new(load_scene(dir.path(), &LoadOptions::default()).expect("loads"));
    let mut generator = MaskGenerator::User(Arc::clone(&scene));
    let frame = generator
        .generate(&RgbImage::new(48, 36), 1)
        .expect("user masks");

    for level in Level::ALL {
        let instance_mask = load_instance_mask(&scene, level, 1)
            .expect("decodes")
            .expect("scene has masks");
        let mut ids: Vec<u32> = instance_mask
            .ids
            .iter()
            .copied()
            .filter(|&id| id != 0)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        let masks = frame.level(level);
        assert!(
            !masks.is_empty(),
            "{level:?}: the synthetic spheres are in view"
        );
        assert_eq!(
            masks
                .iter()
                .map(|scored| scored.instance_id)
                .collect::<Vec<_>>(),
            ids.iter().copied().map(Some).collect::<Vec<_>>()
        );
        for scored in masks {
            let id = scored.instance_id.expect("user masks keep ids");
            let pixels = instance_mask
                .ids
                .iter()
                .filter(|&&value| value == id)
                .count();
            assert_eq!(scored.area, pixels as u64);
            assert_eq!(scored.score, 1.0);
        }
    }
    // No middle folder: middle falls back to the finer of the two nearest levels, small.
    assert_eq!(frame.level(Level::Middle), frame.level(Level::Small));
}

#[test]
fn missing_masks_and_wrong_sizes_are_errors() {
    let dir = tempfile::tempdir().expect("temp dir");
    write_colmap(dir.path(), &spec(None), ColmapEncoding::Text).expect("writes dataset");
    let scene = load_scene(dir.path(), &LoadOptions::default()).expect("loads");
    let mut generator = MaskGenerator::User(Arc::new(scene));
    assert!(matches!(
        generator.generate(&RgbImage::new(48, 36), 0),
        Err(SegmentError::User(UserMaskError::NoUserMasks))
    ));

    let dir = tempfile::tempdir().expect("temp dir");
    write_colmap(
        dir.path(),
        &spec(Some(vec![Level::Large])),
        ColmapEncoding::Text,
    )
    .expect("writes dataset");
    let scene = load_scene(dir.path(), &LoadOptions::default()).expect("loads");
    let mut generator = MaskGenerator::User(Arc::new(scene));
    let error = generator
        .generate(&RgbImage::new(24, 18), 0)
        .expect_err("size mismatch");
    assert!(
        matches!(error, SegmentError::UserMaskSize { .. }),
        "{error}"
    );
}
