//! Shared set-up for the tests that run models (`tests/models/`, `tests/segment/` and, through
//! `tests/common`, the service tests): the ONNX Runtime, the tiny stand-in model directory
//! (tests/fixtures/models/tiny) and copies of it to break.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use segsplat_vision::models::{ModelStore, OrtRuntime, RuntimeOptions};

pub fn tiny_models_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/models/tiny")
}

pub fn clip_fixtures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/clip")
}

/// The runtime, or `None` (with a printed reason) when the library cannot be loaded and
/// `SEGSPLAT_SKIP_ORT_TESTS=1` allows skipping. Without that variable a missing library fails:
/// CI installs the onnxruntime wheel (scripts/bootstrap).
pub fn runtime() -> Option<Arc<OrtRuntime>> {
    let options = RuntimeOptions {
        intra_threads: 2,
        inter_threads: 1,
        ..RuntimeOptions::default()
    };
    match OrtRuntime::load(options) {
        Ok(runtime) => Some(runtime),
        Err(error) if std::env::var("SEGSPLAT_SKIP_ORT_TESTS").as_deref() == Ok("1") => {
            eprintln!("skipping ONNX Runtime test: {error}");
            None
        }
        Err(error) => panic!(
            "ONNX Runtime is needed (pip install onnxruntime, or set ORT_DYLIB_PATH; SEGSPLAT_SKIP_ORT_TESTS=1 skips): {error}"
        ),
    }
}

/// The tiny model store, or `None` when ONNX Runtime tests are skipped.
pub fn tiny_store() -> Option<ModelStore> {
    let runtime = runtime()?;
    Some(ModelStore::open(&tiny_models_dir(), runtime).expect("the tiny model directory opens"))
}

/// A writable copy of the tiny model directory.
pub fn copy_of_tiny_models() -> tempfile::TempDir {
    let copy = tempfile::tempdir().expect("temp dir");
    for entry in std::fs::read_dir(tiny_models_dir()).expect("tiny models dir") {
        let entry = entry.expect("dir entry");
        std::fs::copy(entry.path(), copy.path().join(entry.file_name())).expect("copy");
    }
    copy
}

/// Rewrites `dir/manifest.json` through `edit`.
pub fn edit_manifest(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("manifest.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("manifest")).expect("json");
    edit(&mut manifest);
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&manifest).expect("json"),
    )
    .expect("write");
}

/// The manifest entry of `role` in a manifest JSON value.
pub fn model_of_role<'a>(
    manifest: &'a mut serde_json::Value,
    role: &str,
) -> &'a mut serde_json::Value {
    manifest["models"]
        .as_array_mut()
        .expect("models")
        .iter_mut()
        .find(|model| model["role"] == role)
        .expect("role present")
}

/// A synthetic RGB image: a grey background with filled discs `(centre x, centre y, radius, colour)`.
pub fn discs_image(
    width: u32,
    height: u32,
    discs: &[(f32, f32, f32, [u8; 3])],
) -> (image::RgbImage, Vec<Vec<bool>>) {
    let mut truths = vec![vec![false; (width * height) as usize]; discs.len()];
    let image = image::RgbImage::from_fn(width, height, |x, y| {
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        for (index, (cx, cy, radius, colour)) in discs.iter().enumerate() {
            if (px - cx).powi(2) + (py - cy).powi(2) <= radius * radius {
                truths[index][(y * width + x) as usize] = true;
                return image::Rgb(*colour);
            }
        }
        image::Rgb([128, 128, 128])
    });
    (image, truths)
}

pub fn mask_iou(a: &[bool], b: &[bool]) -> f64 {
    let intersection = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    if union == 0 {
        1.0
    } else {
        intersection as f64 / union as f64
    }
}
