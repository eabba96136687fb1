//! User masks (level fallback, bit depths, validation) and frame images for the engine.

use std::fs;
use std::path::Path;

use segsplat_scene::colmap::{CameraModel, ColmapEncoding};
use segsplat_scene::synthetic::{
    self, SYNTHETIC_BACKGROUND, SyntheticLens, SyntheticSpec, synthetic_objects,
};
use segsplat_scene::{
    InstanceMask, Level, LoadOptions, Scene, SceneError, load_frame_rgb, load_instance_mask,
    load_scene, scale_for_max_side, validate_scene,
};

use crate::formats::colmap_scene;

fn scene_with_masks(levels: Vec<Level>) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().unwrap();
    let spec = SyntheticSpec {
        with_masks: Some(levels),
        ..SyntheticSpec::default()
    };
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Binary).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    (dir, scene)
}

fn distinct_ids(mask: &InstanceMask) -> Vec<u32> {
    let mut ids = mask.ids.clone();
    ids.sort_unstable();
    ids.dedup();
    ids
}

#[test]
fn one_given_level_serves_all_three() {
    let (_dir, scene) = scene_with_masks(vec![Level::Middle]);
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.mask_levels, vec![Level::Middle]);
    for frame_index in 0..scene.frames.len() {
        let middle = load_instance_mask(&scene, Level::Middle, frame_index)
            .unwrap()
            .unwrap();
        assert_eq!((middle.width, middle.height), (32, 24));
        assert!(
            middle.ids.iter().any(|id| *id != 0),
            "frame {frame_index} is empty"
        );
        for level in [Level::Small, Level::Large] {
            let other = load_instance_mask(&scene, level, frame_index)
                .unwrap()
                .unwrap();
            assert_eq!(other, middle);
        }
    }
}

#[test]
fn each_given_level_has_its_own_ids() {
    let (_dir, scene) = scene_with_masks(vec![Level::Small, Level::Middle, Level::Large]);
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.mask_levels, Level::ALL.to_vec());
    // Some view sees all three spheres: 3 objects at small, 2 at middle, 1 at large.
    let found = (0..scene.frames.len()).any(|frame_index| {
        let ids_at = |level| {
            distinct_ids(
                &load_instance_mask(&scene, level, frame_index)
                    .unwrap()
                    .unwrap(),
            )
        };
        ids_at(Level::Small) == [0, 1, 2, 3]
            && ids_at(Level::Middle) == [0, 1, 2]
            && ids_at(Level::Large) == [0, 1]
    });
    assert!(found, "no frame shows the three levels as written");
}

#[test]
fn missing_level_falls_back_to_the_nearest_finer_one() {
    let (_dir, scene) = scene_with_masks(vec![Level::Small, Level::Large]);
    let layout = scene.masks.as_ref().unwrap();
    assert_eq!(layout.source_level(Level::Middle), Some(Level::Small));
    assert_eq!(layout.source_level(Level::Large), Some(Level::Large));
    let middle = load_instance_mask(&scene, Level::Middle, 0).unwrap();
    let small = load_instance_mask(&scene, Level::Small, 0).unwrap();
    assert_eq!(middle, small);
}

#[test]
fn scenes_without_masks_have_none() {
    let (_dir, scene) = scene_with_masks(Vec::new());
    // An empty level list writes no masks folder at all.
    assert!(scene.masks.is_none());
    assert_eq!(load_instance_mask(&scene, Level::Small, 0).unwrap(), None);
}

#[test]
fn a_frame_without_its_mask_is_rejected_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SyntheticSpec {
        with_masks: Some(vec![Level::Large]),
        ..SyntheticSpec::default()
    };
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Text).unwrap();
    fs::remove_file(dir.path().join("masks/large/frame_0001.png")).unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(
        error.to_string().contains("masks/large/frame_0001.png"),
        "{error}"
    );
}

fn validate_with_replaced_mask(write: impl FnOnce(&Path)) -> SceneError {
    let (dir, scene) = scene_with_masks(vec![Level::Small]);
    write(&dir.path().join("masks/small/frame_0002.png"));
    validate_scene(&scene).unwrap_err()
}

#[test]
fn mask_of_the_wrong_size_is_rejected() {
    let error = validate_with_replaced_mask(|path| image::GrayImage::new(8, 8).save(path).unwrap());
    assert!(matches!(error, SceneError::Inconsistent { .. }), "{error}");
    assert!(error.to_string().contains("masks/small/frame_0002.png"));
}

#[test]
fn colour_masks_are_rejected() {
    let error =
        validate_with_replaced_mask(|path| image::RgbImage::new(32, 24).save(path).unwrap());
    assert!(
        matches!(error, SceneError::UndecodableImage { .. }),
        "{error}"
    );
    assert!(error.to_string().contains("single-channel"), "{error}");
}

#[test]
fn undecodable_masks_are_rejected() {
    let error = validate_with_replaced_mask(|path| fs::write(path, b"garbage").unwrap());
    assert!(
        matches!(error, SceneError::UndecodableImage { .. }),
        "{error}"
    );
}

#[test]
fn frame_rgb_keeps_srgb_values_as_unit_floats() {
    let (_dir, scene) = colmap_scene(ColmapEncoding::Binary);
    let image = load_frame_rgb(&scene, 0, None).unwrap();
    assert_eq!(image.dimensions(), (32, 24));
    let corner = image.get_pixel(0, 0).0;
    let background = SYNTHETIC_BACKGROUND.map(|channel| f32::from(channel) / 255.0);
    assert_eq!(corner, background);
    assert!(
        image
            .pixels()
            .all(|pixel| pixel.0.iter().all(|v| (0.0..=1.0).contains(v)))
    );
}

#[test]
fn blender_rgba_is_composited_on_the_configured_background() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_blender(dir.path(), &SyntheticSpec::default()).unwrap();
    let white = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(
        load_frame_rgb(&white, 0, None).unwrap().get_pixel(0, 0).0,
        [1.0; 3]
    );
    let black_options = LoadOptions {
        background: [0.0, 0.0, 0.0],
        ..LoadOptions::default()
    };
    let black = load_scene(dir.path(), &black_options).unwrap();
    let image = load_frame_rgb(&black, 0, None).unwrap();
    assert_eq!(image.get_pixel(0, 0).0, [0.0; 3]);
    // The spheres themselves are opaque and keep their colour whatever the background.
    let centre = image.get_pixel(16, 12).0;
    let on_white = load_frame_rgb(&white, 0, None).unwrap().get_pixel(16, 12).0;
    assert_eq!(centre, on_white);
    assert!(centre.iter().any(|channel| *channel > 0.1));
}

#[test]
fn frame_rgb_downscales_and_intrinsics_follow() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SyntheticSpec {
        width: 40,
        height: 30,
        ..SyntheticSpec::default()
    };
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Binary).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    let full = load_frame_rgb(&scene, 1, Some(64)).unwrap();
    assert_eq!(full.dimensions(), (40, 30), "never upscaled");
    let small = load_frame_rgb(&scene, 1, Some(20)).unwrap();
    assert_eq!(small.dimensions(), (20, 15));
    let factor = scale_for_max_side(40, 30, 20);
    assert_eq!(factor, 0.5);
    let intrinsics = scene.frames[1].intrinsics.scaled(factor);
    assert_eq!((intrinsics.width, intrinsics.height), (20, 15));
    assert_eq!(intrinsics.fx, scene.frames[1].intrinsics.fx / 2.0);
    assert_eq!(intrinsics.cx, 10.0);
    assert_eq!(intrinsics.cy, 7.5);
    // Average colour survives the filter.
    let mean = |image: &image::Rgb32FImage| {
        image.pixels().map(|pixel| pixel.0[0]).sum::<f32>()
            / (image.width() * image.height()) as f32
    };
    assert!((mean(&full) - mean(&small)).abs() < 0.03);
}

/// JPEG frames used below full size decode at a DCT scale (issue 19 item 7): same size and
/// picture as decoding in full and resizing, and a damaged or mis-sized JPEG still fails.
#[test]
fn jpeg_frames_decode_at_a_reduced_scale_like_the_full_decode() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SyntheticSpec {
        width: 320,
        height: 240,
        frame_count: 2,
        image_format: synthetic::SyntheticImageFormat::Jpeg,
        ..SyntheticSpec::default()
    };
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Binary).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    validate_scene(&scene).unwrap();
    // 320 -> 40: the 1/8 DCT scale gives exactly the size asked for.
    let reduced = load_frame_rgb(&scene, 0, Some(40)).unwrap();
    assert_eq!(reduced.dimensions(), (40, 30));
    // The full decode, resized the usual way, for comparison.
    let full = load_frame_rgb(&scene, 0, None).unwrap();
    let resized = image::imageops::resize(&full, 40, 30, image::imageops::FilterType::Triangle);
    let mean_difference = reduced
        .pixels()
        .zip(resized.pixels())
        .flat_map(|(a, b)| (0..3).map(move |c| (a.0[c] - b.0[c]).abs()))
        .sum::<f32>()
        / (40 * 30 * 3) as f32;
    assert!(mean_difference < 0.03, "{mean_difference}");
    // Not a multiple of a DCT scale: decoded at 1/4 (80 x 60), then resized to 50 x 38.
    assert_eq!(
        load_frame_rgb(&scene, 0, Some(50)).unwrap().dimensions(),
        (50, 38)
    );

    // A JPEG cut inside its headers is refused by validation and the reduced decode alike.
    // (Cut inside the scan data, both decoders fill in the rest, as the `image` crate always
    // did.)
    let path = scene.root.join(&scene.frames[1].image_path);
    let bytes = fs::read(&path).unwrap();
    fs::write(&path, &bytes[..120]).unwrap();
    assert!(validate_scene(&scene).is_err());
    assert!(load_frame_rgb(&scene, 1, Some(40)).is_err());
    // A JPEG of another size than its camera says is named as such.
    image::RgbImage::new(160, 120).save(&path).unwrap();
    let error = load_frame_rgb(&scene, 1, Some(40)).unwrap_err().to_string();
    assert!(error.contains("160x120"), "{error}");
}

#[test]
fn scaled_intrinsics_use_the_rounded_image_size() {
    let (_dir, scene) = colmap_scene(ColmapEncoding::Binary);
    let factor = scale_for_max_side(32, 24, 10);
    let image = load_frame_rgb(&scene, 0, Some(10)).unwrap();
    let intrinsics = scene.frames[0].intrinsics.scaled(factor);
    assert_eq!(image.dimensions(), (intrinsics.width, intrinsics.height));
    assert_eq!(image.dimensions(), (10, 8));
    let x_ratio = 10.0 / 32.0;
    assert!((intrinsics.fx - scene.frames[0].intrinsics.fx * x_ratio).abs() < 1e-12);
    assert!((intrinsics.cy - 12.0 * 8.0 / 24.0).abs() < 1e-12);
}

#[test]
fn synthetic_objects_have_distinct_small_ids() {
    let ids: Vec<u32> = synthetic_objects()
        .iter()
        .map(|object| object.ids[0])
        .collect();
    assert_eq!(ids, vec![1, 2, 3]);
}

#[test]
fn source_level_picks_the_nearest_given_level() {
    use segsplat_scene::MaskLayout;
    let layout_with = |levels: &[Level]| {
        let mut layout = MaskLayout::default();
        for level in levels {
            layout.paths[level.index()] = Some(Vec::new());
        }
        layout
    };
    let sources = |levels: &[Level]| {
        let layout = layout_with(levels);
        Level::ALL.map(|level| layout.source_level(level))
    };
    use Level::{Large, Middle, Small};
    assert_eq!(sources(&[]), [None; 3]);
    assert_eq!(sources(&[Large]), [Some(Large); 3]);
    assert_eq!(sources(&[Small]), [Some(Small); 3]);
    assert_eq!(
        sources(&[Small, Large]),
        [Some(Small), Some(Small), Some(Large)]
    );
    assert_eq!(
        sources(&[Middle, Large]),
        [Some(Middle), Some(Middle), Some(Large)]
    );
    assert_eq!(
        sources(&[Small, Middle, Large]),
        [Some(Small), Some(Middle), Some(Large)]
    );
}

#[test]
fn masks_of_a_distorted_camera_are_undistorted_with_their_labels() {
    let spec = |lens| SyntheticSpec {
        frame_count: 3,
        width: 160,
        height: 120,
        with_masks: Some(Level::ALL.to_vec()),
        lens,
        camera_distance: 2.0,
        ..SyntheticSpec::default()
    };
    let (distorted_dir, pinhole_dir) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let lens = SyntheticLens {
        model: CameraModel::OpenCv,
        distortion: vec![-0.35, 0.12, 0.003, -0.004],
    };
    synthetic::write_colmap(
        distorted_dir.path(),
        &spec(Some(lens)),
        ColmapEncoding::Binary,
    )
    .unwrap();
    synthetic::write_colmap(pinhole_dir.path(), &spec(None), ColmapEncoding::Binary).unwrap();
    let distorted = load_scene(distorted_dir.path(), &LoadOptions::default()).unwrap();
    let pinhole = load_scene(pinhole_dir.path(), &LoadOptions::default()).unwrap();
    validate_scene(&distorted).unwrap();
    let share_differing = |a: &InstanceMask, b: &InstanceMask| {
        let differing = a.ids.iter().zip(&b.ids).filter(|(x, y)| x != y).count();
        differing as f64 / a.ids.len() as f64
    };
    for level in Level::ALL {
        for frame_index in 0..distorted.frames.len() {
            let undistorted = load_instance_mask(&distorted, level, frame_index)
                .unwrap()
                .unwrap();
            let reference = load_instance_mask(&pinhole, level, frame_index)
                .unwrap()
                .unwrap();
            let path = distorted
                .masks
                .as_ref()
                .unwrap()
                .path_for(level, frame_index)
                .unwrap();
            let raw = image::open(distorted.root.join(path)).unwrap();
            let (width, height) = (raw.width(), raw.height());
            let ids = match raw {
                image::DynamicImage::ImageLuma8(gray) => {
                    gray.into_raw().into_iter().map(u32::from).collect()
                }
                image::DynamicImage::ImageLuma16(gray) => {
                    gray.into_raw().into_iter().map(u32::from).collect()
                }
                other => panic!("unexpected mask type {:?}", other.color()),
            };
            let raw = InstanceMask { width, height, ids };
            // Labels stay labels: the same set of ids, nothing blended between them.
            assert_eq!(distinct_ids(&undistorted), distinct_ids(&reference));
            let (after, before) = (
                share_differing(&undistorted, &reference),
                share_differing(&raw, &reference),
            );
            println!(
                "{level:?} frame {frame_index}: pixels off the pinhole mask {:.2}% undistorted, {:.2}% as stored",
                after * 100.0,
                before * 100.0
            );
            assert!(after < 0.005, "{level:?} {frame_index}: {after}");
            assert!(
                before > 4.0 * after.max(0.001),
                "{level:?} {frame_index}: {before}"
            );
        }
    }
}
