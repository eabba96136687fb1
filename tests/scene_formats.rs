//! Dataset formats written by the synthetic writers, loaded and validated back.

use std::fs;
use std::path::{Path, PathBuf};

use glam::Mat4;
use segsplat_scene::colmap::{self, CameraModel, ColmapEncoding};
use segsplat_scene::synthetic::{
    self, SyntheticImageFormat, SyntheticLens, SyntheticSpec, synthetic_intrinsics,
    synthetic_world_from_cameras,
};
use segsplat_scene::{
    FrameSplit, InputErrorClass, LoadOptions, Scene, SceneError, SceneFormat, load_frame_rgb,
    load_scene, validate_scene,
};

fn spec() -> SyntheticSpec {
    SyntheticSpec::default()
}

fn assert_pose_close(actual: Mat4, expected: Mat4, label: &str) {
    let difference = (actual - expected).abs().to_cols_array();
    let largest = difference.iter().copied().fold(0.0f32, f32::max);
    assert!(
        largest < 1e-4,
        "{label}: pose differs by {largest}\n{actual}\n{expected}"
    );
}

fn colmap_scene(encoding: ColmapEncoding) -> (tempfile::TempDir, Scene) {
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
            let camera_point = frame
                .world_from_camera
                .inverse()
                .transform_point3(*position);
            let u = frame.intrinsics.fx as f32 * camera_point.x / camera_point.z
                + frame.intrinsics.cx as f32;
            let v = frame.intrinsics.fy as f32 * camera_point.y / camera_point.z
                + frame.intrinsics.cy as f32;
            assert!((u - observation.pixel[0]).abs() < 1e-2);
            assert!((v - observation.pixel[1]).abs() < 1e-2);
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

/// A 4-view synthetic scene at 160x120 through `lens`, the cameras close enough for the spheres
/// to reach the outer part of the frame, where distortion moves pixels most.
fn distorted_spec(lens: Option<SyntheticLens>) -> SyntheticSpec {
    SyntheticSpec {
        frame_count: 4,
        width: 160,
        height: 120,
        lens,
        camera_distance: 2.0,
        ..spec()
    }
}

fn lens(model: CameraModel, distortion: &[f64]) -> Option<SyntheticLens> {
    Some(SyntheticLens {
        model,
        distortion: distortion.to_vec(),
    })
}

/// Strong barrel distortion with tangential terms, as COLMAP OPENCV orders them: k1 k2 p1 p2.
const OPENCV_LENS: [f64; 4] = [-0.35, 0.12, 0.003, -0.004];

/// Per sphere (red, green, blue), the centroid of its colour in `image`: each pixel weighted by
/// how much its sphere's channel exceeds the other two. Resampling keeps centroids to a small
/// fraction of a pixel, so they show where the spheres are in the image.
fn sphere_centroids(image: &image::Rgb32FImage) -> [Option<[f64; 2]>; 3] {
    let mut sums = [[0.0f64; 3]; 3];
    for (x, y, pixel) in image.enumerate_pixels() {
        let [r, g, b] = pixel.0.map(f64::from);
        for (sphere, weight) in [r - g.max(b), g - r.max(b), b - r.max(g)]
            .into_iter()
            .enumerate()
        {
            let weight = weight.max(0.0);
            sums[sphere][0] += weight * (f64::from(x) + 0.5);
            sums[sphere][1] += weight * (f64::from(y) + 0.5);
            sums[sphere][2] += weight;
        }
    }
    sums.map(|[x, y, total]| (total > 20.0).then(|| [x / total, y / total]))
}

/// Largest centroid offset between two images' spheres (spheres seen in both).
fn largest_centroid_offset(a: &image::Rgb32FImage, b: &image::Rgb32FImage) -> f64 {
    sphere_centroids(a)
        .iter()
        .zip(sphere_centroids(b))
        .filter_map(|(a, b)| Some(((*a)?, b?)))
        .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
        .fold(0.0, f64::max)
}

/// Checks the loader's (undistorted) frames against the pinhole rendering of the same views and
/// returns the largest sphere-centroid offset of the images as stored (distorted).
fn assert_undistorted_like_pinhole(distorted: &Scene, pinhole: &Scene, label: &str) -> f64 {
    let pinhole_camera = synthetic_intrinsics(&distorted_spec(None));
    let (mut largest_undistorted, mut largest_stored) = (0.0f64, 0.0f64);
    for (index, frame) in distorted.frames.iter().enumerate() {
        let camera = &frame.intrinsics;
        assert_eq!(
            (camera.fx, camera.fy, camera.cx, camera.cy),
            (
                pinhole_camera.fx,
                pinhole_camera.fy,
                pinhole_camera.cx,
                pinhole_camera.cy
            ),
            "{label}: the pinhole camera keeps fx, fy, cx, cy"
        );
        let undistorted = load_frame_rgb(distorted, index, None).unwrap();
        let reference = load_frame_rgb(pinhole, index, None).unwrap();
        let stored = image::open(distorted.root.join(&frame.image_path))
            .unwrap()
            .into_rgb32f();
        let (after, before) = (
            largest_centroid_offset(&undistorted, &reference),
            largest_centroid_offset(&stored, &reference),
        );
        println!(
            "{label} frame {index}: sphere centroids off the pinhole rendering by {after:.3} px undistorted, {before:.3} px as stored"
        );
        assert!(after < 0.2, "{label} frame {index}: {after} px");
        largest_undistorted = largest_undistorted.max(after);
        largest_stored = largest_stored.max(before);
    }
    assert!(
        largest_stored > 1.0 && largest_stored > 8.0 * largest_undistorted,
        "{label}: the stored images should be off ({largest_stored} px)"
    );
    largest_stored
}

/// Pinhole projection of `point` into `frame` (pixel centres at i + 0.5).
fn project(frame: &segsplat_scene::Frame, point: glam::Vec3) -> [f64; 2] {
    let camera_point = frame.world_from_camera.inverse().transform_point3(point);
    let camera = &frame.intrinsics;
    [
        camera.fx * f64::from(camera_point.x / camera_point.z) + camera.cx,
        camera.fy * f64::from(camera_point.y / camera_point.z) + camera.cy,
    ]
}

#[test]
fn colmap_opencv_frames_are_undistorted_to_the_pinhole_camera() {
    let (distorted_dir, pinhole_dir) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let spec = distorted_spec(lens(CameraModel::OpenCv, &OPENCV_LENS));
    synthetic::write_colmap(distorted_dir.path(), &spec, ColmapEncoding::Text).unwrap();
    synthetic::write_colmap(
        pinhole_dir.path(),
        &distorted_spec(None),
        ColmapEncoding::Text,
    )
    .unwrap();
    let distorted = load_scene(distorted_dir.path(), &LoadOptions::default()).unwrap();
    let pinhole = load_scene(pinhole_dir.path(), &LoadOptions::default()).unwrap();
    let summary = validate_scene(&distorted).unwrap();
    assert_eq!(distorted.frames[0].intrinsics.model, "OPENCV");
    assert_eq!(distorted.frames[0].intrinsics.distortion, OPENCV_LENS);
    // The upload's summary (the scene's description) says what was undistorted.
    assert_eq!(summary.undistorted.len(), 1, "{:?}", summary.undistorted);
    let described = &summary.undistorted[0];
    assert_eq!(described.model, "OPENCV");
    assert_eq!(described.frame_count, 4);
    assert_eq!(
        (described.size, described.undistorted_size),
        ([160, 120], [160, 120])
    );
    let coefficients: Vec<(&str, f64)> = described
        .coefficients
        .iter()
        .map(|c| (c.name.as_str(), c.value))
        .collect();
    assert_eq!(
        coefficients,
        [("k1", -0.35), ("k2", 0.12), ("p1", 0.003), ("p2", -0.004)]
    );
    assert_eq!(
        segsplat_scene::distortion::describe_lens(described),
        "OPENCV k1=-0.35 k2=0.12 p1=0.003 p2=-0.004, 160x120 undistorted to 160x120 pinhole (4 frames)"
    );
    assert!(validate_scene(&pinhole).unwrap().undistorted.is_empty());
    assert_undistorted_like_pinhole(&distorted, &pinhole, "COLMAP OPENCV");

    // Known 3D points: their tracks (COLMAP keypoints, stored where the lens put them) come out
    // at the pinhole projection; the stored keypoints are pixels off.
    let model_location = colmap::find_model(distorted_dir.path()).unwrap();
    let model = colmap::read_model(distorted_dir.path(), &model_location).unwrap();
    let points = distorted.points.as_ref().unwrap();
    let (mut largest_loaded, mut largest_stored, mut observations) = (0.0f64, 0.0f64, 0);
    for (point_index, track) in points.tracks.iter().enumerate() {
        let model_point = &model.points[point_index];
        assert_eq!(
            model_point.track.len(),
            track.len(),
            "no observation is lost"
        );
        for (observation, element) in track.iter().zip(&model_point.track) {
            let frame = &distorted.frames[observation.frame_index as usize];
            let expected = project(frame, points.positions[point_index]);
            let loaded = observation.pixel.map(f64::from);
            let image = model
                .images
                .iter()
                .find(|image| image.id == element.image_id)
                .unwrap();
            let stored = image.points2d[element.point2d_index as usize].xy;
            let distance = |a: [f64; 2]| (a[0] - expected[0]).hypot(a[1] - expected[1]);
            largest_loaded = largest_loaded.max(distance(loaded));
            largest_stored = largest_stored.max(distance(stored));
            observations += 1;
        }
    }
    println!(
        "{observations} observations: largest offset from the pinhole projection {largest_loaded:.2e} px loaded, {largest_stored:.2} px as stored"
    );
    assert!(observations > 100);
    assert!(largest_loaded < 0.01, "{largest_loaded}");
    assert!(largest_stored > 2.0, "{largest_stored}");
}

#[test]
fn other_colmap_lens_models_are_undistorted() {
    let pinhole_dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(
        pinhole_dir.path(),
        &distorted_spec(None),
        ColmapEncoding::Binary,
    )
    .unwrap();
    let pinhole = load_scene(pinhole_dir.path(), &LoadOptions::default()).unwrap();
    for (model, distortion) in [
        (CameraModel::SimpleRadial, vec![-0.3]),
        (CameraModel::Radial, vec![-0.3, 0.08]),
        (
            CameraModel::FullOpenCv,
            vec![-0.3, 0.1, 0.002, -0.003, 0.01, 0.05, 0.01, 0.002],
        ),
        (CameraModel::OpenCvFisheye, vec![0.05, -0.02, 0.004, -0.001]),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let spec = distorted_spec(lens(model, &distortion));
        synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Binary).unwrap();
        let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!(scene.frames[0].intrinsics.model, model.name());
        assert_undistorted_like_pinhole(&scene, &pinhole, model.name());
    }
}

#[test]
fn nerfstudio_opencv_and_fisheye_frames_are_undistorted() {
    let pinhole_dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(pinhole_dir.path(), &distorted_spec(None)).unwrap();
    let pinhole = load_scene(pinhole_dir.path(), &LoadOptions::default()).unwrap();
    for (model, distortion, expected_model) in [
        (CameraModel::OpenCv, OPENCV_LENS.to_vec(), "OPENCV"),
        (
            CameraModel::OpenCvFisheye,
            vec![0.05, -0.02, 0.004, -0.001],
            "OPENCV_FISHEYE",
        ),
    ] {
        let dir = tempfile::tempdir().unwrap();
        synthetic::write_nerfstudio(dir.path(), &distorted_spec(lens(model, &distortion))).unwrap();
        let transforms: serde_json::Value =
            serde_json::from_slice(&fs::read(dir.path().join("transforms.json")).unwrap()).unwrap();
        assert_eq!(transforms["camera_model"], expected_model);
        assert_eq!(transforms["k1"], distortion[0]);
        let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!(scene.frames[0].intrinsics.model, expected_model);
        assert_eq!(scene.frames[0].intrinsics.distortion, distortion);
        assert_undistorted_like_pinhole(&scene, &pinhole, &format!("nerfstudio {expected_model}"));
    }
}

#[test]
fn unsupported_or_broken_lenses_are_refused_naming_file_and_camera() {
    // A thin-prism fisheye COLMAP camera.
    let dir = tempfile::tempdir().unwrap();
    let spec = distorted_spec(lens(CameraModel::ThinPrismFisheye, &[0.0; 8]));
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Text).unwrap_err();
    let spec = distorted_spec(lens(CameraModel::OpenCv, &OPENCV_LENS));
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Text).unwrap();
    let cameras = dir.path().join("sparse/0/cameras.txt");
    let text = fs::read_to_string(&cameras).unwrap();
    let thin_prism = text.replace(" OPENCV ", " THIN_PRISM_FISHEYE ").replace(
        &format!(" {}", OPENCV_LENS[3]),
        &format!(" {} 0 0 0 0", OPENCV_LENS[3]),
    );
    fs::write(&cameras, thin_prism).unwrap();
    let error = load_scene(dir.path(), &LoadOptions::default()).unwrap_err();
    assert_eq!(error.class(), InputErrorClass::Invalid);
    let message = error.to_string();
    assert!(
        message.starts_with(
            "sparse/0/cameras: camera 1: camera model THIN_PRISM_FISHEYE cannot be undistorted"
        ),
        "{message}"
    );
    // A NaN coefficient.
    fs::write(
        &cameras,
        text.replace(&format!(" {}", OPENCV_LENS[1]), " nan"),
    )
    .unwrap();
    let message = load_scene(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with(
            "sparse/0/cameras: camera 1: OPENCV camera: distortion parameter 2 (k2) is NaN"
        ),
        "{message}"
    );

    // nerfstudio: an unknown camera_model, and a coefficient out of f64's range (JSON has no
    // NaN).
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(dir.path(), &distorted_spec(None)).unwrap();
    let path = dir.path().join("transforms.json");
    let original = fs::read_to_string(&path).unwrap();
    let mut transforms: serde_json::Value = serde_json::from_str(&original).unwrap();
    transforms["camera_model"] = serde_json::json!("FISHEYE624");
    fs::write(&path, serde_json::to_vec(&transforms).unwrap()).unwrap();
    let message = load_scene(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        message
            .starts_with("transforms.json: frame 0: camera_model \"FISHEYE624\" is not supported"),
        "{message}"
    );
    fs::write(&path, original.replace("\"k2\": 0.0", "\"k2\": 1e999")).unwrap();
    let message = load_scene(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(message.starts_with("transforms.json: "), "{message}");
}
