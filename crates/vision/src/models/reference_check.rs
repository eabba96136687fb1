//! The real-architecture check: run a model directory (random-weight exports of the real
//! architectures) with segsplat's own preprocessing, tokenizer and prompt driver, and compare to
//! the PyTorch outputs `scripts/export_models.py --reference-dir` saved (`.npy` + `index.json`).
//! Used by `segsplat models verify`; not part of CI (it needs the exports, ~3 GB of torch).

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::clip::{ClipImageEncoder, ClipTextEncoder, clip_pixel_values, l2_normalise};
use super::error::ModelError;
use super::manifest::{Preprocess, Role};
use super::sam::{
    DEFAULT_PROMPT_CHUNK, OBJECT_SCORE_OUTPUT, PointLabel, SamModel, SamPrompt, sam_encoder_input,
};
use super::store::ModelStore;

/// One compared quantity: the largest absolute difference, against a tolerance.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub what: String,
    pub max_abs_error: f64,
    pub tolerance: f64,
}

impl Comparison {
    pub fn passed(&self) -> bool {
        self.max_abs_error <= self.tolerance
    }
}

/// Everything one reference directory produced: comparisons and timings (seconds).
#[derive(Debug, Default)]
pub struct ReferenceReport {
    pub comparisons: Vec<Comparison>,
    pub timings: Vec<(String, f64)>,
    pub notes: Vec<String>,
}

impl ReferenceReport {
    pub fn passed(&self) -> bool {
        self.comparisons.iter().all(Comparison::passed)
    }

    fn compare(
        &mut self,
        what: impl Into<String>,
        actual: &[f32],
        expected: &[f32],
        tolerance: f64,
    ) {
        let max_abs_error = if actual.len() == expected.len() {
            actual
                .iter()
                .zip(expected)
                .map(|(a, b)| f64::from((a - b).abs()))
                .fold(0.0, f64::max)
        } else {
            f64::INFINITY
        };
        let what = if actual.len() == expected.len() {
            what.into()
        } else {
            format!(
                "{} (length {} vs {})",
                what.into(),
                actual.len(),
                expected.len()
            )
        };
        self.comparisons.push(Comparison {
            what,
            max_abs_error,
            tolerance,
        });
    }
}

/// Checks every reference subdirectory of `reference` that `store` has models for.
pub fn check_against_reference(
    store: &ModelStore,
    reference: &Path,
) -> Result<ReferenceReport, ModelError> {
    let mut report = ReferenceReport::default();
    let entries = std::fs::read_dir(reference).map_err(|source| ModelError::Read {
        path: reference.to_path_buf(),
        source,
    })?;
    let mut dirs: Vec<PathBuf> = entries
        .flatten()
        .map(|entry| entry.path())
        .filter(|path| path.is_dir())
        .collect();
    dirs.sort();
    for dir in dirs {
        if dir.join("text_embeds.npy").is_file() && store.has(Role::ClipText) {
            check_clip(store, &dir, &mut report)?;
        } else if dir.join("image_embeddings.npy").is_file() && store.has(Role::SamDecoder) {
            check_sam(store, &dir, &mut report)?;
        } else {
            report
                .notes
                .push(format!("{}: no matching models, skipped", dir.display()));
        }
    }
    Ok(report)
}

fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>), ModelError> {
    let bytes = std::fs::read(path).map_err(|source| ModelError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let bad = |reason: String| ModelError::Input(format!("{}: {reason}", path.display()));
    let npy = npyz::NpyFile::new(&bytes[..]).map_err(|error| bad(error.to_string()))?;
    let shape = npy.shape().iter().map(|dim| *dim as usize).collect();
    let data = npy
        .into_vec::<f32>()
        .map_err(|error| bad(error.to_string()))?;
    Ok((shape, data))
}

fn read_npy_i64(path: &Path) -> Result<Vec<i64>, ModelError> {
    let bytes = std::fs::read(path).map_err(|source| ModelError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let bad = |reason: String| ModelError::Input(format!("{}: {reason}", path.display()));
    let npy = npyz::NpyFile::new(&bytes[..]).map_err(|error| bad(error.to_string()))?;
    npy.into_vec::<i64>()
        .map_err(|error| bad(error.to_string()))
}

fn read_image(path: &Path) -> Result<image::RgbImage, ModelError> {
    image::open(path)
        .map(|image| image.to_rgb8())
        .map_err(|error| ModelError::Input(format!("{}: {error}", path.display())))
}

fn index_notes(dir: &Path) -> Result<serde_json::Value, ModelError> {
    let path = dir.join("index.json");
    let text = std::fs::read_to_string(&path).map_err(|source| ModelError::Read {
        path: path.clone(),
        source,
    })?;
    let index: serde_json::Value = serde_json::from_str(&text)
        .map_err(|error| ModelError::Input(format!("{}: {error}", path.display())))?;
    Ok(index["notes"].clone())
}

fn normalised_rows(data: &[f32], width: usize) -> Vec<f32> {
    data.chunks_exact(width.max(1))
        .flat_map(|row| {
            let mut row = row.to_vec();
            l2_normalise(&mut row);
            row
        })
        .collect()
}

/// The reference subdirectory's name (`mobilesam`, `clip-vit-b-32`), prefixed to every line.
fn directory_label(dir: &Path) -> String {
    dir.file_name()
        .map(|name| name.to_string_lossy().into_owned())
        .unwrap_or_default()
}

fn check_clip(
    store: &ModelStore,
    dir: &Path,
    report: &mut ReferenceReport,
) -> Result<(), ModelError> {
    let label = directory_label(dir);
    let image_encoder = ClipImageEncoder::new(store)?;
    let text_encoder = ClipTextEncoder::new(store, 64)?;
    let image = read_image(&dir.join("image.png"))?;

    let (_, expected_pixels) = read_npy_f32(&dir.join("pixel_values.npy"))?;
    let pixels = clip_pixel_values(&image, image_encoder.preprocess());
    report.compare(
        format!("{label} pixel_values (Rust preprocessing vs open_clip)"),
        &pixels,
        &expected_pixels,
        1e-4,
    );

    let started = Instant::now();
    let embedding = image_encoder.encode_pixel_values(&pixels, 1)?;
    report.timings.push((
        format!("{label} image encoder, 1 image"),
        started.elapsed().as_secs_f64(),
    ));
    let (shape, expected_embeds) = read_npy_f32(&dir.join("image_embeds.npy"))?;
    let width = shape.last().copied().unwrap_or(1);
    report.compare(
        format!("{label} image_embeds (unit length)"),
        &embedding.concat(),
        &normalised_rows(&expected_embeds, width),
        1e-3,
    );

    let notes = index_notes(dir)?;
    let texts: Vec<String> = notes["texts"]
        .as_array()
        .map(|texts| {
            texts
                .iter()
                .filter_map(|text| text.as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default();
    let expected_ids = read_npy_i64(&dir.join("input_ids.npy"))?;
    let tokenizer = text_encoder.tokenizer();
    let mut ids = Vec::new();
    for text in &texts {
        ids.extend(tokenizer.encode(text)?);
    }
    let context = tokenizer.context_length();
    let matching = ids
        .chunks(context)
        .zip(expected_ids.chunks(context))
        .filter(|(a, b)| a == b)
        .count();
    report.notes.push(format!(
        "{label} tokenizer: {matching}/{} texts give open_clip's ids",
        texts.len()
    ));
    report.comparisons.push(Comparison {
        what: format!("{label} input_ids mismatching texts"),
        max_abs_error: (texts.len() - matching) as f64,
        tolerance: 0.0,
    });

    let text_refs: Vec<&str> = texts.iter().map(String::as_str).collect();
    let started = Instant::now();
    let embeddings = text_encoder.encode(&text_refs)?;
    report.timings.push((
        format!("{label} text encoder, {} texts", texts.len()),
        started.elapsed().as_secs_f64(),
    ));
    let flat: Vec<f32> = embeddings
        .iter()
        .flat_map(|row| row.iter().copied())
        .collect();
    let (shape, expected_text) = read_npy_f32(&dir.join("text_embeds.npy"))?;
    let width = shape.last().copied().unwrap_or(1);
    report.compare(
        format!("{label} text_embeds (unit length)"),
        &flat,
        &normalised_rows(&expected_text, width),
        1e-3,
    );
    Ok(())
}

fn check_sam(
    store: &ModelStore,
    dir: &Path,
    report: &mut ReferenceReport,
) -> Result<(), ModelError> {
    let label = directory_label(dir);
    let model = SamModel::new(store)?;
    let encoder = store.session(Role::SamEncoder)?;
    let Preprocess::SamEncoder(preprocess) = &encoder.entry().preprocess else {
        return Err(ModelError::Input(
            "sam_encoder without preprocessing".to_string(),
        ));
    };
    let image = read_image(&dir.join("image.png"))?;

    let (_, expected_input) = read_npy_f32(&dir.join("image.npy"))?;
    let input = sam_encoder_input(&image, preprocess);
    report.compare(
        format!("{label} encoder input (Rust preprocessing vs official transform)"),
        &input.pixels,
        &expected_input,
        // Pillow's 8-bit resize is reproduced exactly; SAM 2.1's float resize to rounding.
        1e-4,
    );

    let started = Instant::now();
    let encoded = model.encode(&image)?;
    report.timings.push((
        format!("{label} encoder (preprocess + run)"),
        started.elapsed().as_secs_f64(),
    ));
    for output in &encoder.entry().outputs {
        let path = dir.join(format!("{}.npy", output.name));
        if !path.is_file() {
            continue;
        }
        let (_, expected) = read_npy_f32(&path)?;
        let actual = encoded
            .feature(&output.name)
            .map(|feature| feature.data.as_slice())
            .unwrap_or(&[]);
        report.compare(format!("{label} {}", output.name), actual, &expected, 1e-3);
    }

    let (_, points) = read_npy_f32(&dir.join("point_coords_original.npy"))?;
    let (_, expected_coords) = read_npy_f32(&dir.join("point_coords.npy"))?;
    let (_, mask_input) = read_npy_f32(&dir.join("mask_input.npy"))?;
    let (_, has_mask_input) = read_npy_f32(&dir.join("has_mask_input.npy"))?;
    let low_res = super::sam::LOW_RES_SIDE * super::sam::LOW_RES_SIDE;
    let prompts: Vec<SamPrompt> = points
        .chunks_exact(2)
        .enumerate()
        .map(|(index, point)| SamPrompt {
            points: vec![([point[0], point[1]], PointLabel::Foreground)],
            bounding_box: None,
            mask_input: (has_mask_input.get(index).copied().unwrap_or(0.0) > 0.5)
                .then(|| mask_input[index * low_res..(index + 1) * low_res].to_vec()),
        })
        .collect();
    let coords: Vec<f32> = points
        .chunks_exact(2)
        .flat_map(|point| {
            let [x, y] = encoded.to_encoder_frame([point[0], point[1]]);
            [x, y, 0.0, 0.0]
        })
        .collect();
    report.compare(
        format!("{label} point_coords in the encoder frame"),
        &coords,
        &expected_coords,
        1e-3,
    );

    let started = Instant::now();
    // The service's own chunk, so a decoder that cannot batch the way the predictor sends
    // prompts fails here rather than in the first automatic-mask run.
    let answers = model.predict(&encoded, &prompts, DEFAULT_PROMPT_CHUNK)?;
    report.notes.push(format!(
        "{label} decoder: {} prompts, {}",
        prompts.len(),
        model.batching().describe()
    ));
    let elapsed = started.elapsed().as_secs_f64();
    report.timings.push((
        format!("{label} decoder, {} prompts", prompts.len()),
        elapsed,
    ));
    let masks: Vec<f32> = answers
        .iter()
        .flat_map(|answer| answer.logits.concat())
        .collect();
    let iou: Vec<f32> = answers
        .iter()
        .flat_map(|answer| answer.predicted_iou.clone())
        .collect();
    let low: Vec<f32> = answers
        .iter()
        .flat_map(|answer| answer.low_res_logits.concat())
        .collect();
    for (name, actual, tolerance) in [
        ("masks", &masks, 2e-3),
        ("iou_predictions", &iou, 1e-3),
        ("low_res_masks", &low, 2e-3),
    ] {
        let (_, expected) = read_npy_f32(&dir.join(format!("{name}.npy")))?;
        report.compare(format!("{label} {name}"), actual, &expected, tolerance);
    }
    let scores_path = dir.join(format!("{OBJECT_SCORE_OUTPUT}.npy"));
    if model.has_object_score() && scores_path.is_file() {
        let scores: Vec<f32> = answers
            .iter()
            .filter_map(|answer| answer.object_score_logit)
            .collect();
        let (_, expected) = read_npy_f32(&scores_path)?;
        report.compare(
            format!("{label} {OBJECT_SCORE_OUTPUT}"),
            &scores,
            &expected,
            1e-3,
        );
    }
    Ok(())
}
