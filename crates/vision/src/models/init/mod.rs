//! `segsplat models init DIR`: writes `manifest.json` for a folder of ONNX files as users bring
//! them. Each graph's role and family are recognised from its signature, shapes and sha256 are
//! read off the files, and preprocessing takes each family's published constants unless the
//! caller says otherwise; only what no graph can tell (a CLIP model trained with other
//! normalisation, MobileSAM against SAM 1 weights) needs an option.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

mod tokenizer;

use tokenizer::tokenizer_entry;

use super::error::ModelError;
use super::manifest::{Family, MANIFEST_FILE, MANIFEST_FORMAT_VERSION, Manifest, Preprocess, Role};
use super::recognise::{Recognised, describe_signature, recognise};
use super::runtime::OrtRuntime;
use super::sam::mask_probe::graph_masks_follow_original_size;
use super::session::{ModelSession, actual_signature};
use super::signature::{ActualTensor, manifest_vs_role};
use super::store::sha256_file;

/// OpenAI CLIP's normalisation (open_clip's default for every OpenAI and most LAION models).
pub const CLIP_MEAN: [f32; 3] = [0.481_454_66, 0.457_827_5, 0.408_210_73];
pub const CLIP_STD: [f32; 3] = [0.268_629_54, 0.261_302_6, 0.275_777_1];
/// SAM 1 / MobileSAM: ImageNet statistics in 0..255.
const SAM_MEAN: [f32; 3] = [123.675, 116.28, 103.53];
const SAM_STD: [f32; 3] = [58.395, 57.12, 57.375];
/// SAM 2.1: ImageNet statistics in 0..1.
const SAM2_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const SAM2_STD: [f32; 3] = [0.229, 0.224, 0.225];
const DEFAULT_CONTEXT_LENGTH: usize = 77;

/// What a graph cannot tell; `None` takes the family's published value.
#[derive(Debug, Clone, Default)]
pub struct InitOptions {
    pub clip_mean: Option<[f32; 3]>,
    pub clip_std: Option<[f32; 3]>,
    /// For graphs whose image input has a dynamic side.
    pub clip_image_size: Option<u32>,
    /// `mobile_sam` for MobileSAM (same signature as SAM 1); else told from the file name.
    pub sam_family: Option<Family>,
    /// Replace an existing manifest.json.
    pub overwrite: bool,
    /// The tokenizer file of a CLIP text model, in the model folder (default: `tokenizer.json`,
    /// else the folder's one `*tokenizer*.json`).
    pub tokenizer: Option<PathBuf>,
}

/// One model `init` recognised.
#[derive(Debug, Clone)]
pub struct InitModel {
    pub file: String,
    pub role: Role,
    pub family: Family,
    /// What was taken by default rather than read off the graph, for the caller to confirm.
    pub assumed: Vec<String>,
    /// Outputs the graph has beyond its role's, listed in the manifest (read when optional).
    pub extra_outputs: Vec<String>,
    /// What a trial run found out about the graph.
    pub findings: Vec<String>,
}

/// What `init` wrote.
#[derive(Debug, Clone)]
pub struct InitReport {
    pub manifest: PathBuf,
    pub models: Vec<InitModel>,
    pub tokenizer: Option<String>,
    /// Files that were left out, with why (an unrecognised graph, a second model for one role).
    pub skipped: Vec<(String, String)>,
}

struct Graph {
    file: String,
    size: u64,
    sha256: String,
    inputs: Vec<ActualTensor>,
    outputs: Vec<ActualTensor>,
    recognised: Recognised,
}

fn init_error(dir: &Path, reason: String) -> ModelError {
    ModelError::Manifest {
        path: dir.join(MANIFEST_FILE),
        reason,
    }
}

/// Recognises every `.onnx` file of `dir` and writes `dir/manifest.json`.
pub fn init_model_dir(
    dir: &Path,
    runtime: &OrtRuntime,
    options: &InitOptions,
) -> Result<InitReport, ModelError> {
    let manifest_path = dir.join(MANIFEST_FILE);
    if manifest_path.exists() && !options.overwrite {
        return Err(init_error(
            dir,
            "already exists; pass --force to replace it".to_string(),
        ));
    }
    let mut by_role: BTreeMap<&'static str, Graph> = BTreeMap::new();
    let mut skipped = Vec::new();
    for file in onnx_files(dir)? {
        let path = dir.join(&file);
        let (session, _) = runtime
            .open_session(&path)
            .map_err(|reason| ModelError::Corrupt {
                role: "model".to_string(),
                file: file.clone(),
                reason,
            })?;
        let (inputs, outputs) = actual_signature(&session);
        drop(session);
        let Some(recognised) = recognise(&inputs, &outputs) else {
            skipped.push((
                file,
                format!(
                    "not a CLIP or SAM-family graph ({})",
                    describe_signature(&inputs, &outputs)
                ),
            ));
            continue;
        };
        let role = recognised.role.as_str();
        if let Some(first) = by_role.get(role) {
            return Err(init_error(
                dir,
                format!(
                    "{} and {file} are both {}; a model directory holds one per role, so move one out",
                    first.file,
                    recognised.describe()
                ),
            ));
        }
        by_role.insert(
            role,
            Graph {
                sha256: sha256_file(&path)?,
                size: file_size(&path)?,
                file,
                inputs,
                outputs,
                recognised,
            },
        );
    }
    if by_role.is_empty() {
        return Err(init_error(
            dir,
            format!(
                "no CLIP or SAM-family .onnx file found in {}",
                dir.display()
            ),
        ));
    }
    check_sam_pair(dir, &by_role)?;
    let sam_family = sam_family(&by_role, options);
    let tokenizer = tokenizer_entry(dir, &by_role, options.tokenizer.as_deref())?;
    let mut models = Vec::new();
    let mut entries = Vec::new();
    for graph in by_role.values() {
        let (entry, model) = manifest_entry(graph, &by_role, sam_family, options, dir)?;
        entries.push(entry);
        models.push(model);
    }
    let mut manifest = json!({
        "format_version": MANIFEST_FORMAT_VERSION,
        "models": entries,
    });
    if let Some(tokenizer) = &tokenizer {
        manifest["tokenizer"] = tokenizer.clone();
    }
    let mut text = manifest_text(&manifest, dir)?;
    check_role_signatures(dir, &text)?;
    if !decoder_masks_follow_original_size(dir, runtime, &text)? {
        for (entry, model) in entries_mut(&mut manifest).zip(models.iter_mut()) {
            if model.role == Role::SamDecoder {
                entry["preprocess"]["mask_source"] = json!("low_res_masks");
                model.findings.push(
                    "its masks output ignores orig_im_size's aspect (segment-anything's export \
                     bakes the crop of its example image): segsplat resizes low_res_masks itself"
                        .to_string(),
                );
            }
        }
        text = manifest_text(&manifest, dir)?;
    }
    write_atomically(&manifest_path, &(text + "\n"))?;
    Ok(InitReport {
        manifest: manifest_path,
        models,
        tokenizer: tokenizer.and_then(|entry| entry["file"].as_str().map(str::to_string)),
        skipped,
    })
}

/// The manifest as written, after checking that the loader reads it.
fn manifest_text(manifest: &Value, dir: &Path) -> Result<String, ModelError> {
    let text = serde_json::to_string_pretty(manifest)
        .map_err(|error| init_error(dir, error.to_string()))?;
    Manifest::parse(&text).map_err(|reason| {
        init_error(
            dir,
            format!("the manifest init made does not parse: {reason}"),
        )
    })?;
    Ok(text)
}

fn entries_mut(manifest: &mut Value) -> impl Iterator<Item = &mut Value> {
    manifest["models"]
        .as_array_mut()
        .into_iter()
        .flat_map(|models| models.iter_mut())
}

/// Each recognised graph against its role's signature (the tensors segsplat feeds and reads by
/// name, their dtypes and ranks), before any trial run: a renamed or retyped input is named here
/// as a signature difference, not left to ONNX Runtime's "Invalid input name" or "Unexpected
/// input data type" at the first run (issue 41, item 13).
fn check_role_signatures(dir: &Path, text: &str) -> Result<(), ModelError> {
    let manifest = Manifest::parse(text).map_err(|reason| init_error(dir, reason))?;
    for entry in &manifest.models {
        let check = manifest_vs_role(entry);
        if !check.is_ok() {
            return Err(ModelError::Signature {
                role: entry.role.to_string(),
                file: entry.file.clone(),
                problems: format!(
                    "recognised as a {} but its signature differs from the one segsplat feeds \
                     and reads by name: {}",
                    entry.role,
                    check
                        .problems
                        .iter()
                        // The manifest was just written from the graph: its tensors are the graph's.
                        .map(|problem| problem.replacen("manifest ", "the graph ", 1))
                        .collect::<Vec<_>>()
                        .join("; ")
                ),
            });
        }
    }
    Ok(())
}

/// One trial run of the decoder, when there is one (see `sam::mask_probe`).
fn decoder_masks_follow_original_size(
    dir: &Path,
    runtime: &OrtRuntime,
    text: &str,
) -> Result<bool, ModelError> {
    let manifest = Manifest::parse(text).map_err(|reason| init_error(dir, reason))?;
    let (Some(decoder), Some(encoder)) = (
        manifest.model(Role::SamDecoder),
        manifest.model(Role::SamEncoder),
    ) else {
        return Ok(true);
    };
    let Preprocess::SamEncoder(encoder_preprocess) = &encoder.preprocess else {
        return Ok(true);
    };
    let (session, provider) = runtime
        .open_session(&dir.join(&decoder.file))
        .map_err(|reason| ModelError::Corrupt {
            role: decoder.role.to_string(),
            file: decoder.file.clone(),
            reason,
        })?;
    let session = ModelSession::new(decoder.clone(), session, provider);
    graph_masks_follow_original_size(&session, encoder_preprocess)
}

fn onnx_files(dir: &Path) -> Result<Vec<String>, ModelError> {
    let read_error = |source| ModelError::Read {
        path: dir.to_path_buf(),
        source,
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(read_error)? {
        let entry = entry.map_err(read_error)?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.ends_with(".onnx") && entry.path().is_file() {
            files.push(name);
        }
    }
    files.sort();
    Ok(files)
}

/// An encoder and a decoder of different SAM generations cannot work together: a SAM 2.1
/// decoder reads the high-resolution features only a SAM 2.1 encoder gives, and a SAM 1 or
/// MobileSAM decoder reads one embedding. Said here, by family, before the manifest's own
/// check would name only the first missing tensor (issue 41, item 13). SAM 1 and MobileSAM
/// share a signature, so only SAM 2 against the others can be told from the graphs.
fn check_sam_pair(dir: &Path, by_role: &BTreeMap<&'static str, Graph>) -> Result<(), ModelError> {
    let (Some(encoder), Some(decoder)) = (
        by_role.get(Role::SamEncoder.as_str()),
        by_role.get(Role::SamDecoder.as_str()),
    ) else {
        return Ok(());
    };
    let sam2 = |graph: &Graph| graph.recognised.family == Family::Sam2;
    if sam2(encoder) == sam2(decoder) {
        return Ok(());
    }
    let generation = |graph: &Graph| {
        if sam2(graph) {
            "SAM 2"
        } else {
            "SAM 1 / MobileSAM"
        }
    };
    Err(init_error(
        dir,
        format!(
            "{} is a {} encoder and {} a {} decoder: they come from different model families \
             and cannot be paired; put the encoder and decoder of one export in the folder",
            encoder.file,
            generation(encoder),
            decoder.file,
            generation(decoder),
        ),
    ))
}

/// SAM 1 and MobileSAM share a signature: the option decides, else a file name with "mobile".
fn sam_family(by_role: &BTreeMap<&'static str, Graph>, options: &InitOptions) -> Family {
    let sam2 = by_role
        .values()
        .any(|graph| graph.recognised.family == Family::Sam2);
    if sam2 {
        return Family::Sam2;
    }
    if let Some(family) = options.sam_family {
        return family;
    }
    let mobile = by_role.values().any(|graph| {
        matches!(graph.recognised.role, Role::SamEncoder | Role::SamDecoder)
            && graph.file.to_ascii_lowercase().contains("mobile")
    });
    if mobile {
        Family::MobileSam
    } else {
        Family::Sam
    }
}

fn model_name(file: &str) -> String {
    file.strip_suffix(".onnx").unwrap_or(file).to_string()
}

fn tensor_specs(tensors: &[ActualTensor]) -> Result<Vec<Value>, String> {
    tensors
        .iter()
        .map(|tensor| {
            let dtype = tensor.dtype.ok_or_else(|| {
                format!(
                    "{} has element type {}, which segsplat does not read",
                    tensor.name, tensor.type_description
                )
            })?;
            Ok(json!({"name": tensor.name, "dtype": dtype.as_str(), "shape": tensor.shape}))
        })
        .collect()
}

fn input_named<'a>(tensors: &'a [ActualTensor], name: &str) -> Option<&'a ActualTensor> {
    tensors.iter().find(|tensor| tensor.name == name)
}

fn fixed_dim(tensors: &[ActualTensor], name: &str, axis: usize) -> Option<i64> {
    input_named(tensors, name)
        .and_then(|tensor| tensor.shape.get(axis).copied())
        .filter(|dim| *dim > 0)
}

fn manifest_entry(
    graph: &Graph,
    by_role: &BTreeMap<&'static str, Graph>,
    sam_family: Family,
    options: &InitOptions,
    dir: &Path,
) -> Result<(Value, InitModel), ModelError> {
    let role = graph.recognised.role;
    let mut assumed = Vec::new();
    let family = match role {
        Role::ClipImage | Role::ClipText => Family::Clip,
        Role::SamEncoder | Role::SamDecoder => sam_family,
    };
    let preprocess = match role {
        Role::ClipImage => {
            if input_named(&graph.inputs, "pixel_values").is_none() {
                let name = graph
                    .inputs
                    .first()
                    .map_or("?", |input| input.name.as_str());
                return Err(init_error(
                    dir,
                    format!(
                        "{}: looks like a CLIP image model, but its image input is named `{name}`; \
                         segsplat feeds it by the name `pixel_values` (re-export with that name)",
                        graph.file
                    ),
                ));
            }
            let size = match (
                fixed_dim(&graph.inputs, "pixel_values", 2),
                options.clip_image_size,
            ) {
                (_, Some(size)) => i64::from(size),
                (Some(size), None) => size,
                (None, None) => {
                    return Err(init_error(
                        dir,
                        format!(
                            "{}: the image input's side is dynamic; pass --clip-image-size",
                            graph.file
                        ),
                    ));
                }
            };
            if options.clip_mean.is_none() || options.clip_std.is_none() {
                assumed.push(
                    "OpenAI CLIP mean/std (pass --clip-mean/--clip-std if the model was trained with others)"
                        .to_string(),
                );
            }
            json!({
                "image_size": size,
                "resize": "shortest_side_center_crop",
                "interpolation": "bicubic",
                "pixel_scale": 1.0,
                "mean": options.clip_mean.unwrap_or(CLIP_MEAN),
                "std": options.clip_std.unwrap_or(CLIP_STD),
            })
        }
        Role::ClipText => {
            let context = fixed_dim(&graph.inputs, "input_ids", 1).unwrap_or_else(|| {
                assumed.push(format!(
                    "context length {DEFAULT_CONTEXT_LENGTH} (the graph's is dynamic)"
                ));
                DEFAULT_CONTEXT_LENGTH as i64
            });
            json!({ "context_length": context })
        }
        Role::SamEncoder => {
            let size = fixed_dim(&graph.inputs, "image", 2).unwrap_or(1024);
            let (resize, scale, mean, std) = if family == Family::Sam2 {
                ("stretch", 1.0, SAM2_MEAN, SAM2_STD)
            } else {
                ("longest_side_pad", 255.0, SAM_MEAN, SAM_STD)
            };
            if family != Family::Sam2 && options.sam_family.is_none() {
                assumed.push(format!(
                    "family {} from the file name (pass --sam-family to say otherwise; both \
                     preprocess alike)",
                    if family == Family::MobileSam {
                        "mobile_sam"
                    } else {
                        "sam"
                    }
                ));
            }
            json!({
                "image_size": size,
                "resize": resize,
                "interpolation": "bilinear",
                "pixel_scale": scale,
                "mean": mean,
                "std": std,
            })
        }
        Role::SamDecoder => {
            let Some(encoder) = by_role.get(Role::SamEncoder.as_str()) else {
                return Err(init_error(
                    dir,
                    format!(
                        "{} is a SAM-family decoder but no encoder was found next to it",
                        graph.file
                    ),
                ));
            };
            json!({
                "encoder": model_name(&encoder.file),
                "multimask_channels": [1, 2, 3],
                "mask_threshold": 0.0,
            })
        }
    };
    let expected_outputs = role_outputs(role);
    let extra_outputs: Vec<String> = graph
        .outputs
        .iter()
        .filter(|output| !expected_outputs.contains(&output.name.as_str()))
        .map(|output| output.name.clone())
        .collect();
    let inputs = tensor_specs(&graph.inputs)
        .map_err(|reason| init_error(dir, format!("{}: {reason}", graph.file)))?;
    let outputs = tensor_specs(&graph.outputs)
        .map_err(|reason| init_error(dir, format!("{}: {reason}", graph.file)))?;
    let entry = json!({
        "name": model_name(&graph.file),
        "role": role.as_str(),
        "family": family_str(family),
        "architecture": model_name(&graph.file),
        "file": graph.file,
        "sha256": graph.sha256,
        "size": graph.size,
        "inputs": inputs,
        "outputs": outputs,
        "preprocess": preprocess,
    });
    Ok((
        entry,
        InitModel {
            file: graph.file.clone(),
            role,
            family,
            assumed,
            extra_outputs,
            findings: Vec::new(),
        },
    ))
}

fn family_str(family: Family) -> &'static str {
    match family {
        Family::Clip => "clip",
        Family::Sam => "sam",
        Family::MobileSam => "mobile_sam",
        Family::Sam2 => "sam2",
    }
}

/// The outputs a role needs by name (docs/models.md); anything else is extra.
fn role_outputs(role: Role) -> &'static [&'static str] {
    match role {
        Role::ClipImage => &["image_embeds"],
        Role::ClipText => &["text_embeds"],
        Role::SamEncoder => &["image_embeddings", "high_res_feats_0", "high_res_feats_1"],
        Role::SamDecoder => &["masks", "iou_predictions", "low_res_masks"],
    }
}

fn file_size(path: &Path) -> Result<u64, ModelError> {
    std::fs::metadata(path)
        .map(|metadata| metadata.len())
        .map_err(|source| ModelError::Read {
            path: path.to_path_buf(),
            source,
        })
}

fn write_atomically(path: &Path, text: &str) -> Result<(), ModelError> {
    let write_error = |source| ModelError::Write {
        path: path.to_path_buf(),
        source,
    };
    let temporary = path.with_extension("json.tmp");
    std::fs::write(&temporary, text).map_err(write_error)?;
    std::fs::rename(&temporary, path).map_err(write_error)
}
