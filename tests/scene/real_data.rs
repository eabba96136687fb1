//! The figurine capture (23 photos, COLMAP binary, PINHOLE) from the shared data folder, when
//! present next to the crate (or where `SEGSPLAT_FIGURINE_DIR` points).

use std::path::PathBuf;

use segsplat_scene::{LoadOptions, SceneFormat, load_frame_rgb, load_scene, validate_scene};

use crate::support::project;

fn figurine_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("SEGSPLAT_FIGURINE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/figurine")
        });
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("skipping: {} is absent", dir.display());
        None
    }
}

#[test]
fn figurine_loads_and_validates() {
    let Some(dir) = figurine_dir() else {
        return;
    };
    let scene = load_scene(&dir, &LoadOptions::default()).unwrap();
    assert_eq!(scene.format, SceneFormat::Colmap);
    assert_eq!(scene.frames.len(), 23);
    assert!(
        scene
            .frames
            .windows(2)
            .all(|pair| pair[0].name < pair[1].name)
    );
    assert!(
        scene
            .frames
            .iter()
            .all(|frame| frame.intrinsics.model == "PINHOLE")
    );
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.frame_count, 23);
    let points = scene.points.as_ref().unwrap();
    println!(
        "figurine: {} points, resolutions {:?}",
        summary.sparse_point_count, summary.resolutions
    );
    assert!(summary.sparse_point_count > 1000);
    assert!(points.tracks.iter().all(|track| track.len() >= 2));
    // Camera centres surround the point cloud's centre rather than sitting on it.
    let centre =
        points.positions.iter().copied().sum::<glam::Vec3>() / points.positions.len() as f32;
    let camera_distances: Vec<f32> = scene
        .frames
        .iter()
        .map(|frame| (frame.world_from_camera.w_axis.truncate() - centre).length())
        .collect();
    assert!(camera_distances.iter().all(|distance| *distance > 0.1));
    // Points project onto their tracked keypoints through the loaded poses and intrinsics.
    let mut errors_px = Vec::new();
    for (position, track) in points.positions.iter().zip(&points.tracks) {
        for observation in track {
            let frame = &scene.frames[observation.frame_index as usize];
            // `project` also fails on a point behind a camera that observes it.
            let [u, v] = project(frame, *position);
            let pixel = observation.pixel.map(f64::from);
            errors_px.push((u - pixel[0]).hypot(v - pixel[1]));
        }
    }
    errors_px.sort_by(f64::total_cmp);
    let median_error_px = errors_px[errors_px.len() / 2];
    println!("figurine: median reprojection error {median_error_px:.3} px");
    assert!(
        median_error_px < 2.0,
        "median reprojection error {median_error_px} px"
    );
    let image = load_frame_rgb(&scene, 0, Some(256)).unwrap();
    assert_eq!(image.width().max(image.height()), 256);
}
