//! Distorted lenses (COLMAP and nerfstudio models): frames and points undistorted to the pinhole
//! camera the engine uses, and lenses it cannot undistort refused naming file and camera.

use std::fs;

use segsplat_scene::colmap::{self, CameraModel, ColmapEncoding};
use segsplat_scene::synthetic::{self, SyntheticLens, SyntheticSpec, synthetic_intrinsics};
use segsplat_scene::{
    InputErrorClass, LoadOptions, Scene, load_frame_rgb, load_scene, validate_scene,
};

use crate::formats::spec;
use crate::support::project;

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
