//! Dynamic-scene datasets: Nerfies/HyperNeRF, Neu3D (extracted frames and videos) and D-NeRF
//! times. Conventions are checked twice: by round trips through the synthetic writers, and by
//! hand-written files whose expected pixels were worked out from each format's own definition.

use std::fs;
use std::path::Path;

use glam::{Mat4, Vec3};
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{self, SyntheticSpec, synthetic_intrinsics};
use segsplat_scene::synthetic_dynamic_formats::{self, nerfies_id, neu3d_camera, write_npy_matrix};
use segsplat_scene::{
    Frame, FrameSplit, InputErrorClass, Level, LoadOptions, Scene, SceneError, SceneFormat,
    VideoFrameOptions, load_frame_rgb, load_scene, validate_scene,
};
use serde_json::json;

fn spec(frame_count: usize) -> SyntheticSpec {
    SyntheticSpec {
        frame_count,
        width: 32,
        height: 24,
        ..SyntheticSpec::default()
    }
}

fn load(dir: &Path) -> Result<Scene, SceneError> {
    load_scene(dir, &LoadOptions::default())
}

fn assert_pose_close(actual: Mat4, expected: Mat4, label: &str) {
    let largest = (actual - expected)
        .abs()
        .to_cols_array()
        .into_iter()
        .fold(0.0f32, f32::max);
    assert!(
        largest < 1e-4,
        "{label}: pose differs by {largest}\n{actual}\n{expected}"
    );
}

fn assert_close(actual: f64, expected: f64, label: &str) {
    assert!(
        (actual - expected).abs() < 1e-4,
        "{label}: {actual} != {expected}"
    );
}

/// Where a frame sees `world_point`, by the pinhole model the engine uses.
fn project(frame: &Frame, world_point: Vec3) -> [f64; 2] {
    let camera_point = frame
        .world_from_camera
        .inverse()
        .transform_point3(world_point);
    assert!(
        camera_point.z > 0.0,
        "{world_point} is behind {}",
        frame.name
    );
    let intrinsics = &frame.intrinsics;
    [
        intrinsics.fx * f64::from(camera_point.x / camera_point.z) + intrinsics.cx,
        intrinsics.fy * f64::from(camera_point.y / camera_point.z) + intrinsics.cy,
    ]
}

fn write_png(path: &Path, width: u32, height: u32) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_pixel(width, height, image::Rgb([90, 120, 150]))
        .save(path)
        .unwrap();
}

fn write_json(path: &Path, value: serde_json::Value) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    fs::write(path, serde_json::to_string_pretty(&value).unwrap()).unwrap();
}

fn expect_error(result: Result<Scene, SceneError>) -> SceneError {
    match result {
        Ok(scene) => panic!("expected an error, loaded {} frames", scene.frames.len()),
        Err(error) => error,
    }
}

// ---- Nerfies / HyperNeRF ----

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

// ---- Neu3D ----

#[test]
fn neu3d_extracted_frames_round_trip_with_times_and_the_test_camera() {
    let spec = SyntheticSpec {
        with_masks: Some(vec![Level::Small]),
        ..spec(4)
    };
    let dir = tempfile::tempdir().unwrap();
    synthetic_dynamic_formats::write_neu3d(dir.path(), &spec, 3).unwrap();
    let scene = load(dir.path()).unwrap();
    assert_eq!(scene.format, SceneFormat::Neu3d);
    assert!(scene.points.is_none(), "Neu3D has no points: random init");
    assert_eq!(scene.frames.len(), 12);
    let poses = synthetic::synthetic_world_from_cameras(&spec);
    for (index, frame) in scene.frames.iter().enumerate() {
        let (camera, frame_index) = (index / 3, index % 3);
        assert_eq!(
            frame.name,
            format!("{}/{frame_index:04}.png", neu3d_camera(camera))
        );
        assert_eq!(
            frame.intrinsics,
            synthetic_intrinsics(&spec),
            "{}",
            frame.name
        );
        assert_pose_close(frame.world_from_camera, poses[camera], &frame.name);
        assert_eq!(frame.time, Some(frame_index as f32 / 2.0), "{}", frame.name);
        let expected_split = if camera == 0 {
            FrameSplit::Test
        } else {
            FrameSplit::Train
        };
        assert_eq!(frame.split, Some(expected_split), "{}", frame.name);
    }
    assert_eq!(scene.frame_times(), vec![0.0, 0.5, 1.0]);
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.format, SceneFormat::Neu3d);
    assert_eq!(summary.frame_count, 12);
    assert_eq!(summary.time_count, 3);
    assert_eq!(summary.sparse_point_count, 0);
    assert_eq!(summary.mask_levels, vec![Level::Small]);
}

/// Two cameras, 60x40 with focal 50 in `poses_bounds.npy`, frames extracted at 30x20:
/// cam00 looks down world -z with x right = +x; cam01 is turned a quarter about z
/// (right = +y, down = +x). cam01 has one frame more than cam00.
fn write_hand_neu3d(dir: &Path) -> [Vec3; 2] {
    let centres = [Vec3::new(0.5, -1.0, 2.0), Vec3::new(-1.0, 0.5, 3.0)];
    // LLFF rows: per matrix row r, [down[r], right[r], back[r], centre[r], hwf[r]].
    let axes = [
        (Vec3::new(0.0, -1.0, 0.0), Vec3::X, Vec3::Z),
        (Vec3::X, Vec3::Y, Vec3::Z),
    ];
    let mut values = Vec::new();
    for ((down, right, back), centre) in axes.iter().zip(centres) {
        let hwf = [40.0, 60.0, 50.0];
        for row in 0..3 {
            values.extend([down[row], right[row], back[row], centre[row]].map(f64::from));
            values.push(hwf[row]);
        }
        values.extend([0.5, 20.0]);
    }
    write_npy_matrix(&dir.join("poses_bounds.npy"), &values, 17).unwrap();
    for (camera, frames) in [("cam00", 2), ("cam01", 3)] {
        for frame in 0..frames {
            write_png(&dir.join(format!("{camera}/images/{frame:04}.png")), 30, 20);
        }
    }
    centres
}

#[test]
fn neu3d_llff_poses_match_a_hand_computed_projection() {
    let dir = tempfile::tempdir().unwrap();
    let centres = write_hand_neu3d(dir.path());
    let scene = load(dir.path()).unwrap();
    // The shortest camera decides: two frames each, the third of cam01 is left out.
    assert_eq!(scene.frames.len(), 4);
    assert_eq!(scene.frame_times(), vec![0.0, 1.0]);
    let offset = Vec3::new(0.3, -0.2, -2.0);
    // cam00 sees the offset as (0.3, 0.2, 2): x = 50 * 0.15 + 30 = 37.5, y = 50 * 0.1 + 20 = 25
    // at 60x40, halved for the 30x20 frames. cam01 sees it as (-0.2, 0.3, 2): (25, 27.5) / 2.
    let expected = [[18.75, 12.5], [12.5, 13.75]];
    for (camera, expected) in expected.iter().enumerate() {
        let frame = &scene.frames[camera * 2];
        assert!(frame.name.starts_with(&format!("cam0{camera}/")));
        assert_eq!((frame.intrinsics.width, frame.intrinsics.height), (30, 20));
        assert_close(frame.intrinsics.fx, 25.0, "fx");
        assert!(
            frame
                .world_from_camera
                .w_axis
                .truncate()
                .distance(centres[camera])
                < 1e-6
        );
        let [u, v] = project(frame, centres[camera] + offset);
        assert_close(u, expected[0], &format!("{} u", frame.name));
        assert_close(v, expected[1], &format!("{} v", frame.name));
    }
    validate_scene(&scene).unwrap();
}

#[test]
fn neu3d_errors_are_invalid_input() {
    type Break = fn(&Path);
    let cases: Vec<(&str, Break, &str)> = vec![
        (
            "more cameras than pose rows",
            |dir| write_png(&dir.join("cam02/images/0000.png"), 30, 20),
            "2 pose rows but 3 cameras",
        ),
        (
            "poses_bounds.npy rows of 15 values",
            |dir| write_npy_matrix(&dir.join("poses_bounds.npy"), &[0.0f64; 30], 15).unwrap(),
            "poses_bounds.npy",
        ),
        (
            "a camera folder with no frames and no video",
            |dir| {
                for frame in 0..2 {
                    fs::remove_file(dir.join(format!("cam00/images/{frame:04}.png"))).unwrap();
                }
            },
            "cam00/images",
        ),
        (
            "frames of another aspect than the poses",
            |dir| {
                for frame in 0..3 {
                    write_png(&dir.join(format!("cam01/images/{frame:04}.png")), 30, 30);
                }
            },
            "the aspect differs",
        ),
        (
            "a rotation that is not one",
            |dir| write_npy_matrix(&dir.join("poses_bounds.npy"), &[1.0f64; 34], 17).unwrap(),
            "poses_bounds.npy",
        ),
    ];
    for (label, break_dataset, needle) in cases {
        let dir = tempfile::tempdir().unwrap();
        write_hand_neu3d(dir.path());
        break_dataset(dir.path());
        let error = expect_error(load(dir.path()));
        assert_eq!(error.class(), InputErrorClass::Invalid, "{label}: {error}");
        assert!(error.to_string().contains(needle), "{label}: {error}");
    }
}

/// Two cameras of six video frames, 32x24 with cameras given at 64x48. ffmpeg encodes them
/// (and the loader decodes them); CI installs it (scripts/bootstrap.sh), so its absence fails
/// here rather than skipping.
fn write_video_neu3d(dir: &Path) -> Vec<Mat4> {
    let spec = spec(2);
    synthetic_dynamic_formats::write_neu3d_videos(dir, &spec, 6)
        .expect("ffmpeg must be installed (scripts/bootstrap.sh) to encode the test videos");
    synthetic::synthetic_world_from_cameras(&spec)
}

#[test]
fn neu3d_videos_are_decoded_once_into_frames() {
    let dir = tempfile::tempdir().unwrap();
    let poses = write_video_neu3d(dir.path());
    let options = LoadOptions {
        video_frames: VideoFrameOptions {
            frame_step: 2,
            max_frames: Some(2),
            max_side: Some(32),
            ..VideoFrameOptions::default()
        },
        ..LoadOptions::default()
    };
    let scene = load_scene(dir.path(), &options).unwrap();
    assert_eq!(scene.format, SceneFormat::Neu3d);
    // Every second frame of six, at most two: video frames 0 and 2, as 00000.jpg and 00001.jpg.
    let names: Vec<&str> = scene.frames.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "cam00/00000.jpg",
            "cam00/00001.jpg",
            "cam01/00000.jpg",
            "cam01/00001.jpg"
        ]
    );
    assert!(!dir.path().join("cam00/images/00002.jpg").exists());
    for (index, frame) in scene.frames.iter().enumerate() {
        assert_eq!(
            frame.intrinsics,
            synthetic_intrinsics(&spec(2)),
            "{}",
            frame.name
        );
        assert_pose_close(frame.world_from_camera, poses[index / 2], &frame.name);
        assert_eq!(frame.time, Some((index % 2) as f32));
    }
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.resolutions, vec![[32, 24]]);
    assert_eq!(summary.time_count, 2);
    // The decoded frame is the rendered view, up to video and JPEG compression.
    let rendered_dir = tempfile::tempdir().unwrap();
    synthetic_dynamic_formats::write_neu3d(rendered_dir.path(), &spec(2), 1).unwrap();
    let rendered = load(rendered_dir.path()).unwrap();
    let decoded_pixels = load_frame_rgb(&scene, 2, None).unwrap();
    let rendered_pixels = load_frame_rgb(&rendered, 1, None).unwrap();
    let mean_difference = decoded_pixels
        .iter()
        .zip(rendered_pixels.iter())
        .map(|(a, b)| (a - b).abs())
        .sum::<f32>()
        / decoded_pixels.len() as f32;
    assert!(mean_difference < 0.06, "mean difference {mean_difference}");
    let leftovers: Vec<_> = fs::read_dir(dir.path().join("cam00"))
        .unwrap()
        .map(|entry| entry.unwrap().file_name())
        .collect();
    assert_eq!(leftovers, ["images"], "no staging folders left behind");

    // The extracted frames make the dataset self-contained: without the videos (and with
    // default options) it loads the same.
    for camera in ["cam00", "cam01"] {
        fs::remove_file(dir.path().join(format!("{camera}.mp4"))).unwrap();
    }
    assert_eq!(load(dir.path()).unwrap(), scene);
}

#[test]
fn neu3d_video_failures_are_classified() {
    // A corrupt video is the upload's fault (422) and leaves no frames behind.
    let dir = tempfile::tempdir().unwrap();
    write_video_neu3d(dir.path());
    fs::write(dir.path().join("cam01.mp4"), b"this is not a video").unwrap();
    let error = expect_error(load(dir.path()));
    assert!(
        matches!(&error, SceneError::UndecodableVideo { file, .. } if file == "cam01.mp4"),
        "{error}"
    );
    assert_eq!(error.class(), InputErrorClass::Invalid);
    let cam01: Vec<_> = fs::read_dir(dir.path().join("cam01"))
        .map(|entries| entries.map(|entry| entry.unwrap().file_name()).collect())
        .unwrap_or_default();
    assert!(cam01.is_empty(), "left behind: {cam01:?}");

    // A server without ffmpeg is the server's fault (500), said plainly.
    let dir = tempfile::tempdir().unwrap();
    write_video_neu3d(dir.path());
    let options = LoadOptions {
        video_frames: VideoFrameOptions {
            ffmpeg: "/nonexistent/ffmpeg".into(),
            ..VideoFrameOptions::default()
        },
        ..LoadOptions::default()
    };
    let error = expect_error(load_scene(dir.path(), &options));
    assert!(
        matches!(error, SceneError::VideoDecoderMissing { .. }),
        "{error}"
    );
    assert_eq!(error.class(), InputErrorClass::Internal);
    assert!(error.to_string().contains("not installed"), "{error}");
}

// ---- D-NeRF and static formats ----

#[test]
fn dnerf_times_are_kept_normalised_and_static_scenes_have_none() {
    let spec = SyntheticSpec {
        with_time: true,
        ..spec(5)
    };
    let dir = tempfile::tempdir().unwrap();
    synthetic::write_blender(dir.path(), &spec).unwrap();
    let scene = load(dir.path()).unwrap();
    assert_eq!(scene.format, SceneFormat::Blender);
    assert!(scene.is_dynamic());
    for frame in &scene.frames {
        // Names are `<split>/r_<index>.png`.
        let stem = frame.name.trim_end_matches(".png");
        let index: f32 = stem.rsplit("r_").next().unwrap().parse().unwrap();
        assert_eq!(frame.time, Some(index / 4.0), "{}", frame.name);
    }
    assert_eq!(scene.frame_times().len(), 5);
    assert_eq!(validate_scene(&scene).unwrap().time_count, 5);

    // A time outside 0..1 is refused rather than silently breaking the normalisation.
    let train_file = dir.path().join("transforms_train.json");
    let mut train: serde_json::Value =
        serde_json::from_slice(&fs::read(&train_file).unwrap()).unwrap();
    train["frames"][0]["time"] = json!(1.5);
    fs::write(&train_file, train.to_string()).unwrap();
    let error = expect_error(load(dir.path()));
    assert_eq!(error.class(), InputErrorClass::Invalid);
    assert!(error.to_string().contains("outside 0..1"), "{error}");

    let static_dir = tempfile::tempdir().unwrap();
    synthetic::write_colmap(static_dir.path(), &spec, ColmapEncoding::Text).unwrap();
    let static_scene = load(static_dir.path()).unwrap();
    assert!(!static_scene.is_dynamic());
    assert!(static_scene.frame_times().is_empty());
    assert_eq!(validate_scene(&static_scene).unwrap().time_count, 0);
}

#[test]
fn unknown_format_lists_the_dynamic_formats() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("notes.txt"), b"hello").unwrap();
    let error = expect_error(load(dir.path()));
    assert_eq!(error.class(), InputErrorClass::UnsupportedFormat);
    let message = error.to_string();
    for format in ["Nerfies", "HyperNeRF", "Neu3D", "D-NeRF"] {
        assert!(message.contains(format), "{message}");
    }
}
