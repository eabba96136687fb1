//! Models as users bring them: folders of ONNX files with the official exporters' signatures
//! and no manifest (tests/fixtures/models/official, written by scripts/make_tiny_models.py).
//! `models init` turns each into a model directory that `check` accepts, and automatic masks
//! run through it with 16 prompts per run, batched where the decoder's graph allows.

use crate::models_support;

use std::path::{Path, PathBuf};

use models_support::{discs_image, mask_iou, tiny_models_dir};
use segsplat_scene::Level;
use segsplat_vision::models::ModelStore;
use segsplat_vision::models::init::{InitOptions, init_model_dir};
use segsplat_vision::models::manifest::{Family, Manifest, MaskSource, Preprocess, Role};
use segsplat_vision::models::sam::{DecoderBatching, SamModel, SamPredictor};
use segsplat_vision::segment::region_prompt::{RegionPrompt, RegionPromptSegmenter};
use segsplat_vision::segment::{AutomaticConfig, MaskGenerator, ScoredMask};

const DISCS: [(f32, f32, f32, [u8; 3]); 3] = [
    (40.0, 40.0, 16.0, [220, 30, 30]),
    (110.0, 45.0, 17.0, [30, 40, 210]),
    (80.0, 90.0, 15.0, [235, 220, 30]),
];

fn official_dir(variant: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/models/official")
        .join(variant)
}

/// A writable copy of `source` without its manifest.json, as a user's download would be.
fn bare_copy(source: &Path) -> tempfile::TempDir {
    let copy = tempfile::tempdir().expect("temp dir");
    for entry in std::fs::read_dir(source).expect("fixture dir") {
        let entry = entry.expect("dir entry");
        if entry.file_name() != "manifest.json" {
            std::fs::copy(entry.path(), copy.path().join(entry.file_name())).expect("copy");
        }
    }
    copy
}

/// `init` then `check` on a bare copy of `source`; `None` when ONNX Runtime tests are skipped.
fn initialised(source: &Path) -> Option<(tempfile::TempDir, Manifest)> {
    let runtime = models_support::runtime()?;
    let copy = bare_copy(source);
    let report = init_model_dir(copy.path(), &runtime, &InitOptions::default())
        .expect("init recognises every file");
    assert!(report.skipped.is_empty(), "{:?}", report.skipped);
    let check = ModelStore::check(copy.path(), &runtime);
    assert!(check.is_ok(), "{check:?}");
    let manifest = Manifest::load(copy.path()).expect("the written manifest loads");
    Some((copy, manifest))
}

/// Automatic masks on the three-disc image, 16 prompts per decoder run; every disc must come out
/// as one mask.
fn automatic_masks(dir: &Path) -> Option<(Vec<ScoredMask>, DecoderBatching)> {
    let (masks, batching, best) = automatic_masks_and_best_iou(dir)?;
    for (index, best) in best.iter().enumerate() {
        assert!(*best > 0.9, "disc {index}: best IoU {best}");
    }
    Some((masks, batching))
}

/// Automatic masks, the decoder's batching, and each disc's best mask IoU.
fn automatic_masks_and_best_iou(
    dir: &Path,
) -> Option<(Vec<ScoredMask>, DecoderBatching, Vec<f64>)> {
    let runtime = models_support::runtime()?;
    let store = ModelStore::open(dir, runtime).expect("store opens");
    let model = SamModel::new(&store).expect("SAM model");
    let batching = model.batching();
    let (image, truths) = discs_image(160, 120, &DISCS);
    let mut generator = MaskGenerator::Automatic {
        segmenter: Box::new(SamPredictor::new(model).with_chunk(16)),
        config: AutomaticConfig {
            points_per_side: 8,
            points_per_batch: 16,
            ..AutomaticConfig::default()
        },
    };
    let masks = generator.generate(&image, 0).expect("automatic masks");
    let all: Vec<ScoredMask> = Level::ALL
        .iter()
        .flat_map(|&level| masks.level(level).iter().cloned())
        .collect();
    let best = truths
        .iter()
        .map(|truth| {
            all.iter()
                .map(|scored| mask_iou(&scored.mask.to_bools(), truth))
                .fold(0.0, f64::max)
        })
        .collect();
    Some((all, batching, best))
}

/// Masks that lie mostly on the grey background rather than on a disc.
fn background_masks(masks: &[ScoredMask]) -> usize {
    let (_, truths) = discs_image(160, 120, &DISCS);
    masks
        .iter()
        .filter(|scored| {
            let bools = scored.mask.to_bools();
            let on_discs = bools
                .iter()
                .enumerate()
                .filter(|(index, inside)| **inside && truths.iter().any(|truth| truth[*index]))
                .count();
            on_discs * 2 < scored.area as usize
        })
        .count()
}

#[test]
fn init_on_the_projects_own_exports_reproduces_the_committed_manifest() {
    let Some((_copy, written)) = initialised(&tiny_models_dir()) else {
        return;
    };
    let committed = Manifest::load(&tiny_models_dir()).expect("committed manifest");
    for role in Role::ALL {
        let (ours, theirs) = (
            written.model(role).expect("role written"),
            committed.model(role).expect("role committed"),
        );
        assert_eq!(ours.file, theirs.file, "{role}");
        assert_eq!(ours.family, theirs.family, "{role}");
        assert_eq!(ours.sha256, theirs.sha256, "{role}");
        assert_eq!(ours.inputs, theirs.inputs, "{role}");
        assert_eq!(ours.outputs, theirs.outputs, "{role}");
        assert_eq!(ours.preprocess, theirs.preprocess, "{role}");
        assert!(ours.size.is_some(), "{role}: init records the size");
    }
    let tokenizer = written.tokenizer.expect("tokenizer entry");
    let expected = committed.tokenizer.expect("committed tokenizer");
    assert_eq!(
        (
            tokenizer.start_token,
            tokenizer.end_token,
            tokenizer.context_length
        ),
        (
            expected.start_token,
            expected.end_token,
            expected.context_length
        )
    );
}

fn mask_source(manifest: &Manifest) -> MaskSource {
    match &manifest
        .model(Role::SamDecoder)
        .expect("decoder")
        .preprocess
    {
        Preprocess::SamDecoder(preprocess) => preprocess.mask_source,
        other => panic!("not a decoder's preprocessing: {other:?}"),
    }
}

#[test]
fn segment_anythings_own_export_decodes_one_prompt_per_run_and_its_baked_crop_is_undone() {
    let Some((copy, manifest)) = initialised(&official_dir("sam")) else {
        return;
    };
    let decoder = manifest.model(Role::SamDecoder).expect("decoder");
    assert_eq!(decoder.family, Family::Sam);
    // Its graph crops at 683 x 1024 whatever the image: init finds out and says to resize the
    // low-resolution masks in segsplat.
    assert_eq!(mask_source(&manifest), MaskSource::LowResMasks);
    let Some((masks, batching)) = automatic_masks(copy.path()) else {
        return;
    };
    assert!(batching.one_prompt_per_run, "{batching:?}");
    // Without an object score the stand-in answers grid points on the background too.
    assert!(background_masks(&masks) > 0);

    // With the graph's own masks the 160 x 120 discs come out stretched and shifted.
    models_support::edit_manifest(copy.path(), |manifest| {
        models_support::model_of_role(manifest, "sam_decoder")["preprocess"]["mask_source"] =
            "graph".into();
    });
    let Some((_, _, best)) = automatic_masks_and_best_iou(copy.path()) else {
        return;
    };
    assert!(
        best.iter().any(|iou| *iou < 0.9),
        "the baked crop should distort some disc: {best:?}"
    );
}

#[test]
fn a_broadcast_mask_input_decoder_batches_prompts_without_a_prior() {
    let Some((copy, manifest)) = initialised(&official_dir("mobilesam")) else {
        return;
    };
    // MobileSAM shares SAM 1's signature; the file name tells them apart.
    assert_eq!(
        manifest.model(Role::SamEncoder).expect("encoder").family,
        Family::MobileSam
    );
    assert_eq!(mask_source(&manifest), MaskSource::Graph);
    let Some((_, batching)) = automatic_masks(copy.path()) else {
        return;
    };
    assert_eq!(
        batching,
        DecoderBatching {
            one_prompt_per_run: false,
            shared_mask_input: true,
        }
    );
}

#[test]
fn sam2_decoders_with_an_object_score_are_accepted_and_the_score_drops_empty_prompts() {
    let Some(runtime) = models_support::runtime() else {
        return;
    };
    let copy = bare_copy(&official_dir("sam2"));
    init_model_dir(copy.path(), &runtime, &InitOptions::default()).expect("init");
    let check = ModelStore::check(copy.path(), &runtime);
    assert!(check.is_ok(), "{check:?}");
    let decoder = check
        .files
        .iter()
        .find(|file| file.role == "sam_decoder")
        .expect("decoder checked");
    assert!(
        decoder
            .notes
            .iter()
            .any(|note| note == "optional output object_score_logits is read"),
        "{:?}",
        decoder.notes
    );
    let manifest = Manifest::load(copy.path()).expect("manifest");
    assert_eq!(
        manifest.model(Role::SamEncoder).expect("encoder").family,
        Family::Sam2
    );
    let Some((masks, batching)) = automatic_masks(copy.path()) else {
        return;
    };
    assert!(batching.batches() && batching.shared_mask_input);
    assert_eq!(
        background_masks(&masks),
        0,
        "the object score says the grey background is no object"
    );

    // Mask propagation: a prompt on the background is "no object", an empty answer.
    let store = ModelStore::open(copy.path(), runtime).expect("store");
    let mut predictor = SamPredictor::new(SamModel::new(&store).expect("model"));
    let (image, _) = discs_image(160, 120, &DISCS);
    RegionPromptSegmenter::set_image(&mut predictor, &image).expect("encode");
    let prompt = |point: [f32; 2]| RegionPrompt {
        bounding_box: None,
        positive_points: vec![point],
        negative_points: Vec::new(),
        mask_input: None,
    };
    let answers = predictor
        .predict_regions(&[prompt([40.0, 40.0]), prompt([5.0, 110.0])])
        .expect("regions");
    assert!(answers[0].mask.area() > 500, "the red disc is found");
    assert_eq!(answers[1].mask.area(), 0, "the background is no object");
    assert_eq!(answers[1].predicted_iou, 0.0);
}

#[test]
fn init_refuses_to_overwrite_and_names_what_it_cannot_use() {
    let Some(runtime) = models_support::runtime() else {
        return;
    };
    let copy = bare_copy(&official_dir("sam"));
    init_model_dir(copy.path(), &runtime, &InitOptions::default()).expect("first init");
    let again = init_model_dir(copy.path(), &runtime, &InitOptions::default())
        .expect_err("a manifest is there");
    assert!(again.to_string().contains("--force"), "{again}");

    // A decoder alone has no encoder to pair with.
    let alone = tempfile::tempdir().expect("temp dir");
    std::fs::copy(
        official_dir("sam").join("sam_vit_b_decoder.onnx"),
        alone.path().join("decoder.onnx"),
    )
    .expect("copy");
    let error =
        init_model_dir(alone.path(), &runtime, &InitOptions::default()).expect_err("no encoder");
    assert!(error.to_string().contains("no encoder"), "{error}");

    // A CLIP text model without its tokenizer.
    let text_only = tempfile::tempdir().expect("temp dir");
    std::fs::copy(
        tiny_models_dir().join("tiny-clip-text.onnx"),
        text_only.path().join("text.onnx"),
    )
    .expect("copy");
    let error = init_model_dir(text_only.path(), &runtime, &InitOptions::default())
        .expect_err("no tokenizer");
    assert!(
        error.to_string().contains("no tokenizer file is there"),
        "{error}"
    );

    // A tokenizer under another name is found when it is the only one (issue 41, item 12),
    // and named with --tokenizer when there are several.
    std::fs::copy(
        tiny_models_dir().join("tokenizer.json"),
        text_only.path().join("clip_tokenizer.json"),
    )
    .expect("copy");
    let report = init_model_dir(text_only.path(), &runtime, &InitOptions::default()).expect("init");
    assert_eq!(report.tokenizer.as_deref(), Some("clip_tokenizer.json"));
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(text_only.path().join("manifest.json")).expect("manifest"),
    )
    .expect("manifest json");
    assert_eq!(manifest["tokenizer"]["file"], "clip_tokenizer.json");
    std::fs::copy(
        tiny_models_dir().join("tokenizer.json"),
        text_only.path().join("other_tokenizer.json"),
    )
    .expect("copy");
    let overwrite = InitOptions {
        overwrite: true,
        ..InitOptions::default()
    };
    let error = init_model_dir(text_only.path(), &runtime, &overwrite).expect_err("ambiguous");
    assert!(error.to_string().contains("--tokenizer"), "{error}");
    let named = InitOptions {
        tokenizer: Some("other_tokenizer.json".into()),
        ..overwrite
    };
    let report = init_model_dir(text_only.path(), &runtime, &named).expect("named");
    assert_eq!(report.tokenizer.as_deref(), Some("other_tokenizer.json"));
}

#[test]
fn clip_models_of_different_widths_are_refused_as_a_pair() {
    let Some(runtime) = models_support::runtime() else {
        return;
    };
    // The tiny image model embeds into 512 values; this text model into 256, and its graph
    // leaves the width dynamic, so only a run can tell.
    let dir = tempfile::tempdir().expect("temp dir");
    for file in ["tiny-clip-image.onnx", "tokenizer.json"] {
        std::fs::copy(tiny_models_dir().join(file), dir.path().join(file)).expect("copy");
    }
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/models/mismatched/clip-text-256.onnx"),
        dir.path().join("clip-text-256.onnx"),
    )
    .expect("copy");
    init_model_dir(dir.path(), &runtime, &InitOptions::default()).expect("init");
    let check = ModelStore::check(dir.path(), &runtime);
    assert!(!check.is_ok());
    let pair = check
        .files
        .iter()
        .find(|file| file.role == "clip pair")
        .expect("the pair is checked");
    let message = pair.result.as_ref().expect_err("refused").to_string();
    assert!(
        message.contains(
            "embeds into 512 values but clip_text clip-text-256 (clip-text-256.onnx) into 256"
        ),
        "{message}"
    );
    let open = ModelStore::open(dir.path(), runtime).expect_err("the store refuses it too");
    assert!(open.to_string().contains("not a pair"), "{open}");
}

/// An encoder and a decoder of different SAM generations are refused by family, before any trial
/// run (issue 41, item 13), and a folder without a manifest says how to write one.
#[test]
fn mixed_sam_generations_are_refused_by_family_and_a_missing_manifest_names_init() {
    let Some(runtime) = models_support::runtime() else {
        return;
    };
    let mixed = tempfile::tempdir().expect("temp dir");
    std::fs::copy(
        official_dir("sam2").join("sam2.1_hiera_tiny.decoder.onnx"),
        mixed.path().join("decoder.onnx"),
    )
    .expect("copy");
    std::fs::copy(
        official_dir("mobilesam").join("mobile_sam_encoder.onnx"),
        mixed.path().join("mobile_sam_encoder.onnx"),
    )
    .expect("copy");
    let error = init_model_dir(mixed.path(), &runtime, &InitOptions::default())
        .expect_err("a SAM 2 decoder with a MobileSAM encoder");
    let message = error.to_string();
    assert!(message.contains("different model families"), "{message}");
    assert!(
        message.contains("SAM 2 decoder") && message.contains("SAM 1 / MobileSAM encoder"),
        "{message}"
    );

    let check = ModelStore::check(mixed.path(), &runtime);
    let missing = check
        .manifest_error
        .expect("no manifest was written")
        .to_string();
    assert!(
        missing.contains("segsplat models init"),
        "a missing manifest names the command: {missing}"
    );
}

/// Replaces every occurrence of `from` in the file by `to`, of the same length, so the protobuf
/// stays valid and every reference to a tensor follows its new name.
fn rename_in_file(path: &Path, from: &str, to: &str) {
    assert_eq!(
        from.len(),
        to.len(),
        "same-length names keep the protobuf valid"
    );
    let mut bytes = std::fs::read(path).expect("read model");
    let mut renamed = 0;
    let mut at = 0;
    while let Some(offset) = bytes[at..]
        .windows(from.len())
        .position(|window| window == from.as_bytes())
    {
        let start = at + offset;
        bytes[start..start + to.len()].copy_from_slice(to.as_bytes());
        renamed += 1;
        at = start + to.len();
    }
    assert!(renamed > 0, "{from} is not in {}", path.display());
    std::fs::write(path, bytes).expect("write model");
}

/// A graph recognised for its role but with an input renamed is refused with the names, as a
/// signature difference before any trial run (not ONNX Runtime's "Invalid input name"), and a
/// CLIP image model whose image input has another name is told so, not that its side is
/// dynamic (issue 41, item 13).
#[test]
fn renamed_inputs_are_named_as_signature_differences() {
    let Some(runtime) = models_support::runtime() else {
        return;
    };
    let sam = bare_copy(&official_dir("sam"));
    rename_in_file(
        &sam.path().join("sam_vit_b_decoder.onnx"),
        "point_coords",
        "point_coordz",
    );
    let message = init_model_dir(sam.path(), &runtime, &InitOptions::default())
        .expect_err("a decoder without point_coords")
        .to_string();
    assert!(message.contains("signature differs"), "{message}");
    assert!(message.contains("point_coords"), "{message}");
    assert!(!message.contains("Invalid input name"), "{message}");

    let clip = tempfile::tempdir().expect("temp dir");
    let image = clip.path().join("image.onnx");
    std::fs::copy(tiny_models_dir().join("tiny-clip-image.onnx"), &image).expect("copy");
    rename_in_file(&image, "pixel_values", "image_pixels");
    let message = init_model_dir(clip.path(), &runtime, &InitOptions::default())
        .expect_err("an image input under another name")
        .to_string();
    assert!(
        message.contains("named `image_pixels`") && message.contains("pixel_values"),
        "{message}"
    );
    assert!(!message.contains("--clip-image-size"), "{message}");
}
