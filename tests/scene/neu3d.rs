//! Neu3D captures: extracted frames and camera videos.

use std::fs;
use std::path::Path;

use glam::{Mat4, Vec3};
use segsplat_scene::synthetic::{self, SyntheticSpec, synthetic_intrinsics};
use segsplat_scene::synthetic_dynamic_formats::{self, neu3d_camera, write_npy_matrix};
use segsplat_scene::{
    FrameSplit, InputErrorClass, Level, LoadOptions, SceneError, SceneFormat, VideoFrameOptions,
    load_frame_rgb, load_scene, validate_scene,
};

use crate::dynamic::{assert_close, expect_error, load, spec, write_png};
use crate::support::{assert_pose_close, project};

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
