//! The model store's load-time checks on the tiny stand-in directory and broken copies of it:
//! every kind of problem gets its own precise error.

use crate::models_support;

use models_support::{copy_of_tiny_models, edit_manifest, model_of_role, tiny_models_dir};
use segsplat_vision::models::{ModelError, ModelStore, Role};

#[test]
fn the_tiny_directory_opens_with_every_role() {
    let Some(store) = models_support::tiny_store() else {
        return;
    };
    for role in Role::ALL {
        assert!(store.has(role), "{role}");
    }
    assert!(store.tokenizer().is_ok());
    let summary = store.summary();
    assert!(
        summary.contains("sam_decoder tiny-sam-decoder"),
        "{summary}"
    );
    let runtime = store.runtime().clone();
    let report = ModelStore::check(&tiny_models_dir(), &runtime);
    assert!(report.is_ok(), "{report:?}");
    // Four models, the tokenizer, and the CLIP image/text pair.
    assert_eq!(report.files.len(), 6);
}

/// A tiny-model copy whose `role` file is replaced by `source`, its hash updated to match.
fn copy_with_file_of_another_role(source: &str, role: &str) -> tempfile::TempDir {
    let copy = copy_of_tiny_models();
    let mut file = String::new();
    edit_manifest(copy.path(), |manifest| {
        file = model_of_role(manifest, role)["file"]
            .as_str()
            .unwrap()
            .to_string();
    });
    std::fs::copy(copy.path().join(source), copy.path().join(&file)).unwrap();
    let hash = segsplat_vision::models::store::sha256_file(&copy.path().join(&file)).unwrap();
    edit_manifest(copy.path(), |manifest| {
        model_of_role(manifest, role)["sha256"] = hash.into();
    });
    copy
}

fn open_copy(dir: &std::path::Path) -> Option<ModelError> {
    let runtime = models_support::runtime()?;
    Some(ModelStore::open(dir, runtime).unwrap_err())
}

#[test]
fn a_flipped_byte_is_a_hash_mismatch() {
    let copy = copy_of_tiny_models();
    let path = copy.path().join("tiny-sam-decoder.onnx");
    let mut bytes = std::fs::read(&path).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x01;
    std::fs::write(&path, bytes).unwrap();
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    assert!(
        matches!(error, ModelError::HashMismatch { .. }),
        "{error:?}"
    );
    let message = error.to_string();
    assert!(
        message.starts_with("sam_decoder tiny-sam-decoder.onnx: sha256 is "),
        "{message}"
    );
    assert!(message.contains("manifest says 51cb3dc9"), "{message}");
}

#[test]
fn a_corrupted_file_with_its_hash_updated_is_reported_as_unreadable() {
    let copy = copy_of_tiny_models();
    let path = copy.path().join("tiny-clip-image.onnx");
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 3]).unwrap();
    let hash = segsplat_vision::models::store::sha256_file(&path).unwrap();
    edit_manifest(copy.path(), |manifest| {
        model_of_role(manifest, "clip_image")["sha256"] = hash.into();
    });
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    assert!(matches!(error, ModelError::Corrupt { .. }), "{error:?}");
    assert!(
        error
            .to_string()
            .starts_with("clip_image tiny-clip-image.onnx: ONNX Runtime cannot open it"),
        "{error}"
    );
}

#[test]
fn a_missing_file_is_named() {
    let copy = copy_of_tiny_models();
    std::fs::remove_file(copy.path().join("tiny-sam-encoder.onnx")).unwrap();
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    assert!(matches!(error, ModelError::MissingFile { .. }), "{error:?}");
    assert!(
        error
            .to_string()
            .starts_with("sam_encoder tiny-sam-encoder.onnx: file not found in "),
        "{error}"
    );
}

#[test]
fn an_unknown_role_is_a_manifest_error() {
    let copy = copy_of_tiny_models();
    edit_manifest(copy.path(), |manifest| {
        model_of_role(manifest, "sam_encoder")["role"] = "sam_encodr".into();
    });
    let error = segsplat_vision::models::Manifest::load(copy.path()).unwrap_err();
    assert!(matches!(error, ModelError::Manifest { .. }), "{error:?}");
    let message = error.to_string();
    assert!(
        message.contains("unknown variant `sam_encodr`"),
        "{message}"
    );
    assert!(message.contains("sam_encoder"), "{message}");
}

#[test]
fn a_manifest_dtype_that_breaks_the_role_is_named() {
    let copy = copy_of_tiny_models();
    edit_manifest(copy.path(), |manifest| {
        let decoder = model_of_role(manifest, "sam_decoder");
        decoder["inputs"][1]["dtype"] = "float16".into();
    });
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    assert!(matches!(error, ModelError::Signature { .. }), "{error:?}");
    assert_eq!(
        error.to_string(),
        "sam_decoder tiny-sam-decoder.onnx: manifest input point_coords has dtype float16, a sam_decoder needs float32"
    );
}

#[test]
fn another_roles_model_is_a_signature_mismatch() {
    // The clip_text graph under the clip_image entry: the manifest is right for the role, the
    // file is not.
    let copy = copy_with_file_of_another_role("tiny-clip-text.onnx", "clip_image");
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    assert!(matches!(error, ModelError::Signature { .. }), "{error:?}");
    let message = error.to_string();
    assert!(
        message.starts_with(
            "clip_image tiny-clip-image.onnx: this looks like a CLIP text model (inputs input_ids; \
             outputs text_embeds), not a clip_image: model has no input pixel_values (its inputs: input_ids)"
        ),
        "{message}"
    );
    assert!(message.ends_with("(and 2 more)"), "{message}");
}

#[test]
fn a_fixed_dimension_the_model_does_not_have_is_named() {
    // The tiny encoder is fixed at 1 x 3 x 1024 x 1024; a manifest claiming a dynamic batch
    // would let callers send batches the model refuses.
    let copy = copy_of_tiny_models();
    edit_manifest(copy.path(), |manifest| {
        model_of_role(manifest, "sam_encoder")["inputs"][0]["shape"][0] = (-1).into();
    });
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    assert_eq!(
        error.to_string(),
        "sam_encoder tiny-sam-encoder.onnx: input image has dimension 0 = 1, manifest says dynamic"
    );
}

#[test]
fn check_reports_every_file_and_keeps_going() {
    let copy = copy_of_tiny_models();
    std::fs::remove_file(copy.path().join("tiny-sam-encoder.onnx")).unwrap();
    let path = copy.path().join("tokenizer.json");
    let mut text = std::fs::read(&path).unwrap();
    text.push(b' ');
    std::fs::write(&path, text).unwrap();
    let Some(runtime) = models_support::runtime() else {
        return;
    };
    let report = ModelStore::check(copy.path(), &runtime);
    assert!(!report.is_ok());
    let failed: Vec<&str> = report
        .files
        .iter()
        .filter(|file| file.result.is_err())
        .map(|file| file.role.as_str())
        .collect();
    assert_eq!(failed, vec!["sam_encoder", "tokenizer"]);
    assert_eq!(report.files.len(), 6);
}

#[test]
fn a_decoder_given_as_the_encoder_says_so_first_and_briefly() {
    let copy = copy_with_file_of_another_role("tiny-sam-decoder.onnx", "sam_encoder");
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    let message = error.to_string();
    assert!(
        message.starts_with(
            "sam_encoder tiny-sam-encoder.onnx: this looks like a SAM decoder (inputs image_embeddings, \
             point_coords, point_labels, mask_input, has_mask_input, orig_im_size; outputs masks, \
             iou_predictions, low_res_masks), not a sam_encoder: "
        ),
        "{message}"
    );
    assert!(message.contains("more)"), "{message}");
    assert!(
        message.len() < 500,
        "{} characters: {message}",
        message.len()
    );
}

#[test]
fn a_truncated_file_is_named_truncated_when_the_manifest_records_its_size() {
    let copy = copy_of_tiny_models();
    let path = copy.path().join("tiny-sam-decoder.onnx");
    let full = std::fs::read(&path).unwrap();
    std::fs::write(&path, &full[..full.len() / 2]).unwrap();
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    assert!(
        error
            .to_string()
            .contains("(the manifest records no size to compare)"),
        "{error}"
    );
    edit_manifest(copy.path(), |manifest| {
        model_of_role(manifest, "sam_decoder")["size"] = full.len().into();
    });
    let Some(error) = open_copy(copy.path()) else {
        return;
    };
    let message = error.to_string();
    assert!(
        message.contains(&format!(
            "the file is {} bytes, the manifest says {}: it looks truncated",
            full.len() / 2,
            full.len()
        )),
        "{message}"
    );
}
