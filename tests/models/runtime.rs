//! ONNX Runtime loading: the library is found and loaded, its version read, and a missing or
//! wrong library is a clear error rather than a panic.

use crate::models_support;

use std::path::Path;

use segsplat_vision::models::ModelError;
use segsplat_vision::models::runtime::{library_version, locate_library, required_minor_version};

#[test]
fn runtime_loads_and_reports_a_supported_version() {
    let Some(runtime) = models_support::runtime() else {
        return;
    };
    let version = runtime.version();
    let minor: u32 = version
        .split('.')
        .nth(1)
        .and_then(|minor| minor.parse().ok())
        .unwrap_or_else(|| panic!("version {version:?}"));
    assert!(version.starts_with("1."), "{version}");
    assert!(minor >= required_minor_version(), "{version}");
    assert!(runtime.library().is_file());
    assert_eq!(library_version(runtime.library()).unwrap(), version);
}

#[test]
fn a_configured_library_that_does_not_exist_is_named() {
    let error = locate_library(Some(Path::new("/nonexistent/libonnxruntime.so"))).unwrap_err();
    assert!(
        matches!(error, ModelError::LibraryNotFound { .. }),
        "{error:?}"
    );
    let message = error.to_string();
    assert!(
        message.contains("models.ort_library = /nonexistent/libonnxruntime.so"),
        "{message}"
    );
    assert!(message.contains("ORT_DYLIB_PATH"), "{message}");
}

#[test]
fn a_file_that_is_not_onnx_runtime_is_a_load_error() {
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("libonnxruntime.so");
    std::fs::write(&fake, b"not a shared library").unwrap();
    let error = library_version(&fake).unwrap_err();
    assert!(matches!(error, ModelError::LibraryLoad { .. }), "{error:?}");
    assert!(error.to_string().contains("libonnxruntime.so"), "{error}");
}

#[test]
fn sessions_are_shared_across_threads() {
    let Some(store) = models_support::tiny_store() else {
        return;
    };
    let encoder = segsplat_vision::models::clip::ClipTextEncoder::new(&store, 16).unwrap();
    let encoder = std::sync::Arc::new(encoder);
    let handles: Vec<_> = ["red", "blue", "green", "yellow"]
        .into_iter()
        .map(|word| {
            let encoder = encoder.clone();
            std::thread::spawn(move || encoder.encode(&[word]).unwrap().remove(0))
        })
        .collect();
    for handle in handles {
        let embedding = handle.join().unwrap();
        let norm: f32 = embedding.iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-5);
    }
}

#[test]
fn readiness_reports_a_missing_library_when_models_are_configured() {
    use segsplat_service::config::ModelsConfig;
    use segsplat_vision::models::ModelsStatus;
    let status = ModelsStatus::load(&ModelsConfig {
        dir: Some(models_support::tiny_models_dir()),
        ort_library: Some("/nonexistent/libonnxruntime.so".into()),
        ..ModelsConfig::default()
    });
    let (ok, detail) = status.readiness();
    assert!(!ok);
    assert!(
        detail.contains("/nonexistent/libonnxruntime.so"),
        "{detail}"
    );
    assert!(status.store().is_err());

    let (ok, detail) = ModelsStatus::load(&ModelsConfig::default()).readiness();
    assert!(ok);
    assert_eq!(detail, "none configured");
}

#[test]
fn readiness_lists_the_loaded_models() {
    if models_support::runtime().is_none() {
        return;
    }
    let status =
        segsplat_vision::models::ModelsStatus::load(&segsplat_service::config::ModelsConfig {
            dir: Some(models_support::tiny_models_dir()),
            ..Default::default()
        });
    let (ok, detail) = status.readiness();
    assert!(ok, "{detail}");
    assert!(
        detail.contains("clip_text tiny-clip-text (CPUExecutionProvider)"),
        "{detail}"
    );
}
