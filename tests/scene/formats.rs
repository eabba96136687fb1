//! Dataset formats written by the synthetic writers, loaded and validated back.

use std::fs;
use std::path::{Path, PathBuf};

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{
    self, SyntheticImageFormat, SyntheticSpec, synthetic_intrinsics, synthetic_world_from_cameras,
};
use segsplat_scene::{
    FrameSplit, InputErrorClass, LoadOptions, Scene, SceneError, SceneFormat, load_scene,
    validate_scene,
};

use crate::support::{assert_pose_close, project};

pub(crate) fn spec() -> SyntheticSpec {
    SyntheticSpec::default()
}

/// The default synthetic scene written as COLMAP and loaded back (the folder lives as long as
/// the returned `TempDir`).
pub(crate) fn colmap_scene(encoding: ColmapEncoding) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(dir.path(), &spec(), encoding).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    (dir, scene)
}

#[test]
fn colmap_text_and_binary_give_the_same_scene() {
    let (_text_dir, mut text) = colmap_scene(ColmapEncoding::Text);
    let (_binary_dir, binary) = colmap_scene(ColmapEncoding::Binary);
    text.root = binary.root.clone();
    assert_eq!(text, binary);
}

#[test]
fn colmap_scene_matches_what_was_written() {
    let spec = spec();
    let (_dir, scene) = colmap_scene(ColmapEncoding::Binary);
    assert_eq!(scene.format, SceneFormat::Colmap);
    let names: Vec<&str> = scene
        .frames
        .iter()
        .map(|frame| frame.name.as_str())
        .collect();
    let expected_names: Vec<String> = (0..spec.frame_count)
        .map(|index| format!("frame_{index:04}.png"))
        .collect();
    assert_eq!(names, expected_names, "frames must come sorted by name");
    let poses = synthetic_world_from_cameras(&spec);
    for (index, frame) in scene.frames.iter().enumerate() {
        assert_eq!(frame.intrinsics, synthetic_intrinsics(&spec));
        assert_eq!(frame.image_path, PathBuf::from("images").join(&frame.name));
        assert_eq!(frame.source_id, Some(index as u32 + 1));
        assert_pose_close(frame.world_from_camera, poses[index], &frame.name);
    }
    let points = scene.points.as_ref().unwrap();
    assert_eq!(points.positions.len(), 144);
    // Every track observation reprojects onto its pixel through the loaded pose.
    let mut observations = 0;
    for (position, track) in points.positions.iter().zip(&points.tracks) {
        for observation in track {
            let frame = &scene.frames[observation.frame_index as usize];
            let [u, v] = project(frame, *position);
            assert!((u - f64::from(observation.pixel[0])).abs() < 1e-2);
            assert!((v - f64::from(observation.pixel[1])).abs() < 1e-2);
            observations += 1;
        }
    }
    assert!(observations > 100, "only {observations} observations");

    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.frame_count, spec.frame_count as u32);
    assert_eq!(summary.resolutions, vec![[32, 24]]);
    assert_eq!(summary.sparse_point_count, 144);
    assert!(summary.mask_levels.is_empty());
}

#[test]
fn colmap_with_jpeg_images_validates() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SyntheticSpec {
        image_format: SyntheticImageFormat::Jpeg,
        ..spec()
    };
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Text).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert!(scene.frames[0].name.ends_with(".jpg"));
    validate_scene(&scene).unwrap();
}

#[test]
fn colmap_model_directly_under_sparse_is_found() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(dir.path(), &spec(), ColmapEncoding::Text).unwrap();
    let sparse = dir.path().join("sparse");
    for file in ["cameras.txt", "images.txt", "points3D.txt"] {
        fs::rename(sparse.join("0").join(file), sparse.join(file)).unwrap();
    }
    fs::remove_dir(sparse.join("0")).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.frames.len(), spec().frame_count);
}

#[test]
fn a_single_wrapping_folder_is_looked_through() {
    let dir = tempfile::tempdir().unwrap();
    let wrapped = dir.path().join("my_capture");
    synthetic::write_colmap(&wrapped, &spec(), ColmapEncoding::Binary).unwrap();
    fs::create_dir(dir.path().join("__MACOSX")).unwrap();
    fs::write(dir.path().join(".DS_Store"), b"junk").unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.root, wrapped);
    validate_scene(&scene).unwrap();
}

#[test]
fn no_dataset_is_an_unknown_format_listing_what_was_found() {
    let dir = tempfile::tempdir().unwrap();
    fs::create_dir(dir.path().join("photos")).unwrap();
    fs::write(dir.path().join("readme.txt"), b"hi").unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(matches!(error, SceneError::UnknownFormat { .. }), "{error}");
    assert_eq!(error.class(), InputErrorClass::UnsupportedFormat);
    let message = error.to_string();
    assert!(
        message.contains("photos/") && message.contains("readme.txt"),
        "{message}"
    );
}

#[test]
fn nerfstudio_loads_with_opencv_poses() {
    let spec = spec();
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(dir.path(), &spec).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.format, SceneFormat::Nerfstudio);
    // The writer ships the sphere surface points as sparse_pc.ply (8-bit colours).
    let points = scene.points.as_ref().unwrap();
    assert_eq!(points.positions.len(), 144);
    assert!(points.tracks.iter().all(Vec::is_empty));
    let objects = synthetic::synthetic_objects();
    let first_color = objects[0].color.map(|channel| f32::from(channel) / 255.0);
    assert_eq!(points.colors[0].to_array(), first_color);
    let on_first_sphere = (points.positions[0] - objects[0].center).length();
    assert!((on_first_sphere - objects[0].radius).abs() < 1e-5);
    let poses = synthetic_world_from_cameras(&spec);
    let expected = synthetic_intrinsics(&spec);
    for (index, frame) in scene.frames.iter().enumerate() {
        assert_eq!(frame.name, format!("frame_{index:04}.png"));
        assert_eq!(
            frame.image_path,
            Path::new("images").join(format!("frame_{index:04}.png"))
        );
        assert_eq!(
            (
                frame.intrinsics.fx,
                frame.intrinsics.cx,
                frame.intrinsics.cy
            ),
            (expected.fx, expected.cx, expected.cy)
        );
        assert_eq!(frame.intrinsics.model, "OPENCV");
        assert_eq!(frame.intrinsics.distortion, vec![0.0; 4]);
        assert_pose_close(frame.world_from_camera, poses[index], &frame.name);
    }
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.sparse_point_count, 144);
    assert_eq!(summary.frame_count, spec.frame_count as u32);
}

#[test]
fn nerfstudio_per_frame_intrinsics_override_global_ones() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(dir.path(), &spec()).unwrap();
    let path = dir.path().join("transforms.json");
    let mut transforms: serde_json::Value =
        serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
    transforms["frames"][0]["fl_x"] = serde_json::json!(50.0);
    transforms["frames"][0]["k1"] = serde_json::json!(0.1);
    transforms["frames"][0]["k3"] = serde_json::json!(0.01);
    fs::write(&path, serde_json::to_vec(&transforms).unwrap()).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    // The writer lists frames in reverse, so file frame 0 is the last by name.
    let overridden = scene.frames.last().unwrap();
    assert_eq!(overridden.intrinsics.fx, 50.0);
    assert_eq!(overridden.intrinsics.model, "FULL_OPENCV");
    assert_eq!(
        overridden.intrinsics.distortion,
        vec![0.1, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0]
    );
    assert_eq!(scene.frames[0].intrinsics.fx, 0.9 * 32.0);
}

#[test]
fn nerfstudio_missing_focal_length_names_the_field() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(dir.path(), &spec()).unwrap();
    let path = dir.path().join("transforms.json");
    let mut transforms: serde_json::Value =
        serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
    transforms.as_object_mut().unwrap().remove("fl_x");
    fs::write(&path, serde_json::to_vec(&transforms).unwrap()).unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains("transforms.json") && message.contains("fl_x"),
        "{message}"
    );
    assert_eq!(error.class(), InputErrorClass::Invalid);
}

/// instant-ngp's samples written on Windows name their images with backslashes (issue 41, item 6).
#[test]
fn transforms_file_paths_with_windows_separators_load() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(dir.path(), &spec()).unwrap();
    let path = dir.path().join("transforms.json");
    let mut transforms: serde_json::Value =
        serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
    for frame in transforms["frames"].as_array_mut().unwrap() {
        let file_path = frame["file_path"].as_str().unwrap().replace('/', "\\");
        frame["file_path"] = serde_json::json!(file_path);
    }
    assert!(
        transforms["frames"][0]["file_path"]
            .as_str()
            .unwrap()
            .contains('\\')
    );
    fs::write(&path, serde_json::to_vec(&transforms).unwrap()).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(
        scene.frames[0].image_path,
        Path::new("images").join("frame_0000.png")
    );
}

#[test]
fn transforms_file_paths_may_not_leave_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(dir.path(), &spec()).unwrap();
    let path = dir.path().join("transforms.json");
    let mut transforms: serde_json::Value =
        serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
    transforms["frames"][0]["file_path"] = serde_json::json!("../../etc/passwd");
    fs::write(&path, serde_json::to_vec(&transforms).unwrap()).unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(matches!(error, SceneError::Parse { .. }), "{error}");
}

/// A Blender upload's own test split decides what is held out; with only
/// `transforms_train.json` every 8th frame is, as for any other format (issue 41, item 4).
#[test]
fn blender_held_out_frames_follow_its_test_split_or_every_eighth() {
    use segsplat_engine::train::views::is_held_out;
    let spec = SyntheticSpec {
        frame_count: 16,
        ..spec()
    };
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_blender(dir.path(), &spec).unwrap();
    let held_out = |scene: &Scene| -> Vec<String> {
        (0..scene.frames.len())
            .filter(|&index| is_held_out(scene, index, 8))
            .map(|index| scene.frames[index].name.clone())
            .collect()
    };
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    let tests: Vec<String> = scene
        .frames
        .iter()
        .filter(|frame| frame.split == Some(FrameSplit::Test))
        .map(|frame| frame.name.clone())
        .collect();
    assert_eq!(tests.len(), 4);
    assert_eq!(held_out(&scene), tests);
    fs::remove_file(dir.path().join("transforms_test.json")).unwrap();
    fs::remove_dir_all(dir.path().join("test")).unwrap();
    let train_only = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(train_only.frames.len(), 12);
    let every_eighth: Vec<String> = [0, 8]
        .iter()
        .map(|&index| train_only.frames[index].name.clone())
        .collect();
    assert_eq!(held_out(&train_only), every_eighth);
}

#[test]
fn blender_loads_splits_times_and_intrinsics() {
    let spec = SyntheticSpec {
        frame_count: 8,
        with_time: true,
        ..spec()
    };
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_blender(dir.path(), &spec).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.format, SceneFormat::Blender);
    let splits: Vec<FrameSplit> = scene
        .frames
        .iter()
        .map(|frame| frame.split.unwrap())
        .collect();
    assert_eq!(
        splits,
        [
            [FrameSplit::Train; 6].as_slice(),
            [FrameSplit::Test; 2].as_slice()
        ]
        .concat()
    );
    let expected = synthetic_intrinsics(&spec);
    let poses = synthetic_world_from_cameras(&spec);
    let train_then_test: Vec<usize> = (0..8)
        .filter(|index| !synthetic::is_synthetic_test_frame(*index))
        .chain((0..8).filter(|index| synthetic::is_synthetic_test_frame(*index)))
        .collect();
    for (frame, source_index) in scene.frames.iter().zip(train_then_test) {
        assert!((frame.intrinsics.fx - expected.fx).abs() < 1e-9);
        assert!((frame.intrinsics.fy - expected.fy).abs() < 1e-9);
        assert_eq!((frame.intrinsics.width, frame.intrinsics.height), (32, 24));
        assert!(frame.image_path.to_string_lossy().ends_with(".png"));
        let expected_time = source_index as f32 / 7.0;
        assert!((frame.time.unwrap() - expected_time).abs() < 1e-6);
        assert_pose_close(frame.world_from_camera, poses[source_index], &frame.name);
    }
    assert_eq!(scene.frames[0].name, "train/r_0.png");
    validate_scene(&scene).unwrap();
}

fn broken_colmap(break_it: impl FnOnce(&Path)) -> SceneError {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(dir.path(), &spec(), ColmapEncoding::Binary).unwrap();
    break_it(dir.path());
    match load_scene(dir.path(), &LoadOptions::default()) {
        Ok(scene) => validate_scene(&scene).unwrap_err(),
        Err(error) => error,
    }
}

#[test]
fn missing_image_is_named() {
    let error = broken_colmap(|root| fs::remove_file(root.join("images/frame_0002.png")).unwrap());
    assert!(matches!(error, SceneError::MissingImage { .. }), "{error}");
    assert!(error.to_string().contains("images/frame_0002.png"));
    assert_eq!(error.class(), InputErrorClass::Invalid);
}

#[test]
fn undecodable_image_is_named() {
    let error = broken_colmap(|root| {
        fs::write(root.join("images/frame_0001.png"), b"not really a png").unwrap()
    });
    assert!(
        matches!(error, SceneError::UndecodableImage { .. }),
        "{error}"
    );
    assert!(error.to_string().contains("images/frame_0001.png"));
}

#[test]
fn image_size_mismatch_is_reported() {
    let error = broken_colmap(|root| {
        image::RgbImage::new(16, 16)
            .save(root.join("images/frame_0003.png"))
            .unwrap()
    });
    assert!(matches!(error, SceneError::Inconsistent { .. }), "{error}");
    let message = error.to_string();
    assert!(
        message.contains("frame_0003.png")
            && message.contains("16x16")
            && message.contains("32x24"),
        "{message}"
    );
}

#[test]
fn truncated_colmap_binary_is_a_parse_error() {
    let error = broken_colmap(|root| {
        let path = root.join("sparse/0/images.bin");
        let bytes = fs::read(&path).unwrap();
        fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    });
    assert!(matches!(error, SceneError::Parse { .. }), "{error}");
    assert!(error.to_string().contains("sparse/0/images.bin"));
}

#[test]
fn colmap_text_with_a_bad_number_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(dir.path(), &spec(), ColmapEncoding::Text).unwrap();
    let path = dir.path().join("sparse/0/cameras.txt");
    let text = fs::read_to_string(&path)
        .unwrap()
        .replace(" 32 24 ", " 32 twenty ");
    fs::write(&path, text).unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains("sparse/0/cameras.txt") && message.contains("line 2"),
        "{message}"
    );
}

#[test]
fn image_referencing_an_unknown_camera_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(dir.path(), &spec(), ColmapEncoding::Text).unwrap();
    let path = dir.path().join("sparse/0/cameras.txt");
    let text = fs::read_to_string(&path)
        .unwrap()
        .replace("\n1 PINHOLE", "\n7 PINHOLE");
    fs::write(&path, text).unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(error.to_string().contains("camera 1"), "{error}");
}

#[test]
fn colmap_image_names_may_not_leave_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(dir.path(), &spec(), ColmapEncoding::Text).unwrap();
    let path = dir.path().join("sparse/0/images.txt");
    let text = fs::read_to_string(&path)
        .unwrap()
        .replace(" frame_0001.png", " ../../frame_0001.png");
    fs::write(&path, text).unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(matches!(error, SceneError::Parse { .. }), "{error}");
    assert!(
        error.to_string().contains("../../frame_0001.png"),
        "{error}"
    );
}

// Lens distortion: datasets rendered through a known distorted lens load as pinhole frames.
