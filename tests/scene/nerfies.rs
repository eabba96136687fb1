//! Nerfies / HyperNeRF captures.

use std::fs;
use std::path::Path;

use glam::Vec3;
use segsplat_scene::synthetic::{self, SyntheticSpec, synthetic_intrinsics};
use segsplat_scene::synthetic_dynamic_formats::{self, nerfies_id, write_npy_matrix};
use segsplat_scene::{
    FrameSplit, InputErrorClass, Level, LoadOptions, SceneFormat, load_scene, validate_scene,
};
use serde_json::json;

use crate::dynamic::{assert_close, expect_error, load, spec, write_json, write_png};
use crate::support::{assert_pose_close, project};

#[test]
fn nerfies_round_trip_gives_poses_intrinsics_times_splits_and_points() {
    let spec = SyntheticSpec {
        with_masks: Some(vec![Level::Small]),
        ..spec(6)
    };
    let dir = tempfile::tempdir().unwrap();
    synthetic_dynamic_formats::write_nerfies(dir.path(), &spec).unwrap();
    let scene = load(dir.path()).unwrap();
    assert_eq!(scene.format, SceneFormat::Nerfies);
    assert!(scene.is_dynamic());
    assert_eq!(scene.frames.len(), 6);
    let poses = synthetic::synthetic_world_from_cameras(&spec);
    for (index, frame) in scene.frames.iter().enumerate() {
        assert_eq!(frame.name, format!("{}.png", nerfies_id(index)));
        // Cameras are stored at 2x; the rgb/2x images bring them back to the written size.
        assert_eq!(
            frame.intrinsics,
            synthetic_intrinsics(&spec),
            "{}",
            frame.name
        );
        // Positions were stored as p / scale + center and must come back normalised.
        assert_pose_close(frame.world_from_camera, poses[index], &frame.name);
        assert_close(
            f64::from(frame.time.unwrap()),
            index as f64 / 5.0,
            &frame.name,
        );
        let expected_split = if synthetic::is_synthetic_test_frame(index) {
            FrameSplit::Val
        } else {
            FrameSplit::Train
        };
        assert_eq!(frame.split, Some(expected_split), "{}", frame.name);
    }
    // points.npy, normalised like the cameras, equals the surface points the static writers use.
    let reference_dir = tempfile::tempdir().unwrap();
    synthetic::write_nerfstudio(reference_dir.path(), &spec).unwrap();
    let reference = load(reference_dir.path()).unwrap().points.unwrap();
    let points = scene.points.as_ref().unwrap();
    assert_eq!(points.positions.len(), reference.positions.len());
    for (actual, expected) in points.positions.iter().zip(&reference.positions) {
        assert!(actual.distance(*expected) < 1e-4, "{actual} != {expected}");
    }
    assert!(points.colors.iter().all(|color| *color == Vec3::splat(0.5)));

    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.format, SceneFormat::Nerfies);
    assert_eq!(summary.frame_count, 6);
    assert_eq!(summary.time_count, 6);
    assert_eq!(summary.resolutions, vec![[32, 24]]);
    assert_eq!(summary.sparse_point_count, 144);
    assert_eq!(summary.mask_levels, vec![Level::Small]);
}

/// A Nerfies capture written by hand: frame `a` has `time_id` 3, frame `b` only `warp_id` 6;
/// scene.json centre (1, 0, 0) and scale 0.5; images at 2x (32x24) and 4x (16x12).
fn write_hand_nerfies(dir: &Path) {
    write_json(
        &dir.join("dataset.json"),
        json!({"count": 2, "ids": ["a", "b"], "train_ids": ["a"], "val_ids": ["b"]}),
    );
    write_json(
        &dir.join("metadata.json"),
        json!({"a": {"time_id": 3, "warp_id": 0}, "b": {"warp_id": 6}}),
    );
    write_json(
        &dir.join("scene.json"),
        json!({"center": [1.0, 0.0, 0.0], "scale": 0.5, "near": 0.1, "far": 5.0}),
    );
    for id in ["a", "b"] {
        // Camera axes in world coordinates as rows: x = +y, y = +z, z (forward) = +x; not
        // symmetric, so reading it transposed would show.
        write_json(
            &dir.join(format!("camera/{id}.json")),
            json!({
                "orientation": [[0, 1, 0], [0, 0, 1], [1, 0, 0]],
                "position": [1.0, 2.0, 3.0],
                "focal_length": 50.0,
                "principal_point": [31.0, 25.0],
                "skew": 0.0,
                "pixel_aspect_ratio": 1.1,
                "radial_distortion": [0.1, 0.0, 0.0],
                "tangential_distortion": [0.0, 0.0],
                "image_size": [64, 48],
            }),
        );
        write_png(&dir.join(format!("rgb/2x/{id}.png")), 32, 24);
        write_png(&dir.join(format!("rgb/4x/{id}.png")), 16, 12);
    }
    write_npy_matrix(
        &dir.join("points.npy"),
        &[1.0f64, 0.0, 0.0, 3.0, 2.0, 1.0],
        3,
    )
    .unwrap();
}

#[test]
fn nerfies_camera_conventions_match_a_hand_computed_projection() {
    let dir = tempfile::tempdir().unwrap();
    write_hand_nerfies(dir.path());
    let scene = load(dir.path()).unwrap();
    let frame = &scene.frames[0];
    // Centre (1, 2, 3) normalised: ((1 - 1) * 0.5, 2 * 0.5, 3 * 0.5); looking along world +x.
    assert!(
        frame
            .world_from_camera
            .w_axis
            .truncate()
            .distance(Vec3::new(0.0, 1.0, 1.5))
            < 1e-6
    );
    assert!(frame.world_from_camera.z_axis.truncate().distance(Vec3::X) < 1e-6);
    // World point centre + (2, 0.3, 0.2) (raw units) is orientation * offset = (0.3, 0.2, 2)
    // in the camera. Nerfies projects it at x = 50 * 0.3 / 2 + 31 = 38.5,
    // y = 50 * 1.1 * 0.2 / 2 + 25 = 30.5 at full resolution, so (19.25, 15.25) in rgb/2x.
    // Normalised: ((3 - 1) * 0.5, 2.3 * 0.5, 3.2 * 0.5).
    let world_point = Vec3::new(1.0, 1.15, 1.6);
    let [u, v] = project(frame, world_point);
    assert_close(u, 19.25, "u at 2x");
    assert_close(v, 15.25, "v at 2x");
    assert_eq!((frame.intrinsics.width, frame.intrinsics.height), (32, 24));
    assert_eq!(frame.intrinsics.model, "OPENCV");
    assert_eq!(frame.intrinsics.distortion, vec![0.1, 0.0, 0.0, 0.0]);
    // time_id 3 and warp_id 6 (the fallback) over their maximum.
    assert_eq!(scene.frames[0].time, Some(0.5));
    assert_eq!(scene.frames[1].time, Some(1.0));
    assert_eq!(scene.frames[0].split, Some(FrameSplit::Train));
    assert_eq!(scene.frames[1].split, Some(FrameSplit::Val));
    let points = &scene.points.as_ref().unwrap().positions;
    assert!(points[0].distance(Vec3::ZERO) < 1e-6, "{}", points[0]);
    assert!(
        points[1].distance(Vec3::new(1.0, 1.0, 0.5)) < 1e-6,
        "{}",
        points[1]
    );

    // A chosen scale folder scales the same camera further.
    let options = LoadOptions {
        nerfies_scale: Some(4),
        ..LoadOptions::default()
    };
    let scene_4x = load_scene(dir.path(), &options).unwrap();
    let frame_4x = &scene_4x.frames[0];
    assert_eq!(frame_4x.image_path, Path::new("rgb/4x/a.png"));
    assert_close(frame_4x.intrinsics.fx, 12.5, "fx at 4x");
    assert_close(frame_4x.intrinsics.fy, 13.75, "fy at 4x");
    let [u, v] = project(frame_4x, world_point);
    assert_close(u, 9.625, "u at 4x");
    assert_close(v, 7.625, "v at 4x");
    validate_scene(&scene_4x).unwrap();

    let missing_scale = LoadOptions {
        nerfies_scale: Some(8),
        ..LoadOptions::default()
    };
    let error = expect_error(load_scene(dir.path(), &missing_scale));
    assert_eq!(error.class(), InputErrorClass::Invalid);
    assert!(error.to_string().contains("rgb/8x"), "{error}");
}

#[test]
fn nerfies_errors_name_the_file_and_are_invalid_input() {
    type Break = fn(&Path);
    let cases: Vec<(&str, Break, &str)> = vec![
        (
            "missing camera json",
            |dir| fs::remove_file(dir.join("camera/000002.json")).unwrap(),
            "camera/000002.json",
        ),
        (
            "points.npy with two columns",
            |dir| write_npy_matrix(&dir.join("points.npy"), &[1.0f32, 2.0, 3.0, 4.0], 2).unwrap(),
            "points.npy",
        ),
        (
            "points.npy that is not an array",
            |dir| fs::write(dir.join("points.npy"), b"not numpy").unwrap(),
            "points.npy",
        ),
        (
            "missing image",
            |dir| fs::remove_file(dir.join("rgb/2x/000001.png")).unwrap(),
            "rgb/2x/000001.png",
        ),
        (
            "malformed dataset.json",
            |dir| fs::write(dir.join("dataset.json"), b"{\"ids\": [").unwrap(),
            "dataset.json",
        ),
        (
            "an id that climbs out of the dataset",
            |dir| {
                write_json(&dir.join("dataset.json"), json!({"ids": ["../000001"]}));
            },
            "dataset.json",
        ),
        (
            "metadata without the frame",
            |dir| write_json(&dir.join("metadata.json"), json!({})),
            "metadata.json",
        ),
        (
            "camera json without orientation",
            |dir| {
                write_json(
                    &dir.join("camera/000003.json"),
                    json!({"position": [0, 0, 0]}),
                )
            },
            "camera/000003.json",
        ),
        (
            "image of the wrong size for its camera",
            |dir| write_png(&dir.join("rgb/2x/000004.png"), 20, 20),
            "rgb/2x/000004.png",
        ),
    ];
    for (label, break_dataset, file) in cases {
        let dir = tempfile::tempdir().unwrap();
        synthetic_dynamic_formats::write_nerfies(dir.path(), &spec(6)).unwrap();
        break_dataset(dir.path());
        let error = expect_error(load(dir.path()));
        assert_eq!(error.class(), InputErrorClass::Invalid, "{label}: {error}");
        assert!(error.to_string().contains(file), "{label}: {error}");
    }
}

#[test]
fn a_nerfies_capture_wrapped_in_a_folder_is_found() {
    let dir = tempfile::tempdir().unwrap();
    synthetic_dynamic_formats::write_nerfies(&dir.path().join("broom"), &spec(4)).unwrap();
    let scene = load(dir.path()).unwrap();
    assert_eq!(scene.format, SceneFormat::Nerfies);
    assert!(scene.root.ends_with("broom"));
}
