//! What the dynamic-format tests ([`crate::nerfies`], [`crate::neu3d`]) share, and D-NeRF's
//! times. Conventions are checked twice: by round trips through the synthetic writers, and by
//! hand-written files whose expected pixels were worked out from each format's own definition.

use std::fs;
use std::path::Path;

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{self, SyntheticSpec};
use segsplat_scene::{
    InputErrorClass, LoadOptions, Scene, SceneError, SceneFormat, load_scene, validate_scene,
};
use serde_json::json;

pub(crate) fn spec(frame_count: usize) -> SyntheticSpec {
    SyntheticSpec {
        frame_count,
        width: 32,
        height: 24,
        ..SyntheticSpec::default()
    }
}

pub(crate) fn load(dir: &Path) -> Result<Scene, SceneError> {
    load_scene(dir, &LoadOptions::default())
}

pub(crate) fn assert_close(actual: f64, expected: f64, label: &str) {
    assert!(
        (actual - expected).abs() < 1e-4,
        "{label}: {actual} != {expected}"
    );
}

pub(crate) fn write_png(path: &Path, width: u32, height: u32) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_pixel(width, height, image::Rgb([90, 120, 150]))
        .save(path)
        .unwrap();
}

pub(crate) fn write_json(path: &Path, value: serde_json::Value) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    fs::write(path, serde_json::to_string_pretty(&value).unwrap()).unwrap();
}

pub(crate) fn expect_error(result: Result<Scene, SceneError>) -> SceneError {
    match result {
        Ok(scene) => panic!("expected an error, loaded {} frames", scene.frames.len()),
        Err(error) => error,
    }
}

// D-NeRF and static formats

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
