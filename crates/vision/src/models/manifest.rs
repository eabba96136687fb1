//! `manifest.json` of a model directory (docs/models.md): which file plays which role, its sha256,
//! its input/output signature and its preprocessing constants.

use std::fmt;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::ModelError;

/// The manifest format this code reads.
pub const MANIFEST_FORMAT_VERSION: u32 = 1;
pub const MANIFEST_FILE: &str = "manifest.json";

/// What a model is used for; a directory holds at most one model per role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    ClipImage,
    ClipText,
    SamEncoder,
    SamDecoder,
}

impl Role {
    pub const ALL: [Role; 4] = [
        Role::ClipImage,
        Role::ClipText,
        Role::SamEncoder,
        Role::SamDecoder,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Role::ClipImage => "clip_image",
            Role::ClipText => "clip_text",
            Role::SamEncoder => "sam_encoder",
            Role::SamDecoder => "sam_decoder",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    Clip,
    /// SAM 1 (ViT-B/L/H).
    Sam,
    MobileSam,
    /// SAM 2.1: the encoder adds `high_res_feats_0/1`, which the decoder reads.
    Sam2,
}

/// Element types, spelled as numpy spells them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dtype {
    Float32,
    Float16,
    Float64,
    Bfloat16,
    Int64,
    Int32,
    Int16,
    Int8,
    Uint8,
    Bool,
}

impl Dtype {
    pub fn as_str(self) -> &'static str {
        match self {
            Dtype::Float32 => "float32",
            Dtype::Float16 => "float16",
            Dtype::Float64 => "float64",
            Dtype::Bfloat16 => "bfloat16",
            Dtype::Int64 => "int64",
            Dtype::Int32 => "int32",
            Dtype::Int16 => "int16",
            Dtype::Int8 => "int8",
            Dtype::Uint8 => "uint8",
            Dtype::Bool => "bool",
        }
    }
}

impl fmt::Display for Dtype {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One graph input or output: name, element type, one entry per dimension (`-1` = dynamic).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TensorSpec {
    pub name: String,
    pub dtype: Dtype,
    pub shape: Vec<i64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClipResize {
    ShortestSideCenterCrop,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SamResize {
    /// SAM 1 / MobileSAM: longest side to `image_size`, zero padding bottom/right after normalising.
    LongestSidePad,
    /// SAM 2.1: both sides to `image_size`.
    Stretch,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    Bicubic,
    Bilinear,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipImagePreprocess {
    pub image_size: u32,
    pub resize: ClipResize,
    pub interpolation: Interpolation,
    /// A pixel is `u8 / 255 * pixel_scale` before mean/std (1.0: 0..1, 255.0: 0..255).
    pub pixel_scale: f32,
    pub mean: [f32; 3],
    pub std: [f32; 3],
    /// Whether the graph already L2-normalises `image_embeds`; segsplat normalises either way.
    #[serde(default)]
    pub output_normalized: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipTextPreprocess {
    pub context_length: usize,
    /// Whether the graph already L2-normalises `text_embeds`; segsplat normalises either way.
    #[serde(default)]
    pub output_normalized: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SamEncoderPreprocess {
    pub image_size: u32,
    pub resize: SamResize,
    pub interpolation: Interpolation,
    /// 255.0: mean/std are in 0..255 (SAM 1, MobileSAM); 1.0: in 0..1 (SAM 2.1).
    pub pixel_scale: f32,
    pub mean: [f32; 3],
    pub std: [f32; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SamDecoderPreprocess {
    /// Name of the paired `sam_encoder` model.
    pub encoder: String,
    /// Decoder output channels for small, middle, large.
    pub multimask_channels: [usize; 3],
    pub mask_threshold: f32,
    /// Where full-resolution masks come from.
    #[serde(default)]
    pub mask_source: MaskSource,
}

/// Where a decoder's full-resolution masks come from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskSource {
    /// The graph's `masks` output.
    #[default]
    Graph,
    /// segsplat resizes `low_res_masks` itself: for graphs whose `masks` are wrong for most
    /// image shapes (segment-anything's own export bakes the crop of its example image).
    LowResMasks,
}

/// Preprocessing constants, typed by role.
#[derive(Debug, Clone, PartialEq)]
pub enum Preprocess {
    ClipImage(ClipImagePreprocess),
    ClipText(ClipTextPreprocess),
    SamEncoder(SamEncoderPreprocess),
    SamDecoder(SamDecoderPreprocess),
}

/// One model as the manifest describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelEntry {
    pub name: String,
    pub role: Role,
    pub family: Family,
    pub architecture: String,
    pub file: String,
    pub sha256: String,
    /// The file's size in bytes, when the manifest records it: a hash mismatch then says whether
    /// the file is truncated or a different one.
    pub size: Option<u64>,
    pub inputs: Vec<TensorSpec>,
    pub outputs: Vec<TensorSpec>,
    pub preprocess: Preprocess,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenizerEntry {
    pub file: String,
    pub sha256: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<u64>,
    pub context_length: usize,
    pub start_token: u32,
    pub end_token: u32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Manifest {
    pub format_version: u32,
    pub models: Vec<ModelEntry>,
    pub tokenizer: Option<TokenizerEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawManifest {
    format_version: u32,
    models: Vec<RawModelEntry>,
    #[serde(default)]
    tokenizer: Option<TokenizerEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModelEntry {
    name: String,
    role: Role,
    family: Family,
    architecture: String,
    file: String,
    sha256: String,
    #[serde(default)]
    size: Option<u64>,
    inputs: Vec<TensorSpec>,
    outputs: Vec<TensorSpec>,
    preprocess: serde_json::Value,
}

impl Manifest {
    /// Reads and validates `dir/manifest.json`.
    pub fn load(dir: &Path) -> Result<Manifest, ModelError> {
        let path = dir.join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| {
            if source.kind() == std::io::ErrorKind::NotFound {
                // A folder of ONNX files as downloaded: say how to describe it.
                ModelError::Manifest {
                    path: path.clone(),
                    reason: format!(
                        "is missing; run `segsplat models init {}` to write it from the \
                         folder's .onnx files",
                        dir.display()
                    ),
                }
            } else {
                ModelError::Read {
                    path: path.clone(),
                    source,
                }
            }
        })?;
        Manifest::parse(&text).map_err(|reason| ModelError::Manifest { path, reason })
    }

    /// Parses manifest text; the error says what and where.
    pub fn parse(text: &str) -> Result<Manifest, String> {
        let raw: RawManifest = serde_json::from_str(text).map_err(|error| error.to_string())?;
        if raw.format_version != MANIFEST_FORMAT_VERSION {
            return Err(format!(
                "format_version {} is not supported (this segsplat reads {MANIFEST_FORMAT_VERSION})",
                raw.format_version
            ));
        }
        let mut models = Vec::with_capacity(raw.models.len());
        for entry in raw.models {
            models.push(typed_entry(entry)?);
        }
        let manifest = Manifest {
            format_version: raw.format_version,
            models,
            tokenizer: raw.tokenizer,
        };
        manifest.check_consistency()?;
        Ok(manifest)
    }

    pub fn model(&self, role: Role) -> Option<&ModelEntry> {
        self.models.iter().find(|model| model.role == role)
    }

    fn check_consistency(&self) -> Result<(), String> {
        for role in Role::ALL {
            let names: Vec<&str> = self
                .models
                .iter()
                .filter(|model| model.role == role)
                .map(|model| model.name.as_str())
                .collect();
            if names.len() > 1 {
                return Err(format!(
                    "more than one {role} model ({}); a directory holds at most one per role",
                    names.join(", ")
                ));
            }
        }
        for model in &self.models {
            if !is_sha256_hex(&model.sha256) {
                return Err(format!(
                    "model {}: sha256 must be 64 hex digits, got {:?}",
                    model.name, model.sha256
                ));
            }
            check_plain_file_name(&model.file).map_err(|reason| {
                format!("model {}: file {:?} {reason}", model.name, model.file)
            })?;
        }
        if let Some(tokenizer) = &self.tokenizer {
            if !is_sha256_hex(&tokenizer.sha256) {
                return Err(format!(
                    "tokenizer: sha256 must be 64 hex digits, got {:?}",
                    tokenizer.sha256
                ));
            }
            check_plain_file_name(&tokenizer.file)
                .map_err(|reason| format!("tokenizer: file {:?} {reason}", tokenizer.file))?;
            if tokenizer.context_length < 2 {
                return Err("tokenizer: context_length must be >= 2".to_string());
            }
        }
        if let Some(decoder) = self.model(Role::SamDecoder) {
            let Preprocess::SamDecoder(preprocess) = &decoder.preprocess else {
                return Err(format!(
                    "model {}: preprocess is not a decoder's",
                    decoder.name
                ));
            };
            match self.model(Role::SamEncoder) {
                Some(encoder) if encoder.name == preprocess.encoder => {}
                Some(encoder) => {
                    return Err(format!(
                        "model {}: preprocess.encoder is {:?} but the sam_encoder is {:?}",
                        decoder.name, preprocess.encoder, encoder.name
                    ));
                }
                None => {
                    return Err(format!(
                        "model {}: a sam_decoder needs a sam_encoder ({:?}) in the same manifest",
                        decoder.name, preprocess.encoder
                    ));
                }
            }
        }
        Ok(())
    }
}

fn typed_entry(raw: RawModelEntry) -> Result<ModelEntry, String> {
    let context = |error: serde_json::Error| {
        format!(
            "model {}: preprocess for role {}: {error}",
            raw.name, raw.role
        )
    };
    let preprocess = match raw.role {
        Role::ClipImage => {
            Preprocess::ClipImage(serde_json::from_value(raw.preprocess.clone()).map_err(context)?)
        }
        Role::ClipText => {
            Preprocess::ClipText(serde_json::from_value(raw.preprocess.clone()).map_err(context)?)
        }
        Role::SamEncoder => {
            Preprocess::SamEncoder(serde_json::from_value(raw.preprocess.clone()).map_err(context)?)
        }
        Role::SamDecoder => {
            Preprocess::SamDecoder(serde_json::from_value(raw.preprocess.clone()).map_err(context)?)
        }
    };
    check_preprocess(&raw.name, &preprocess)?;
    Ok(ModelEntry {
        name: raw.name,
        role: raw.role,
        family: raw.family,
        architecture: raw.architecture,
        file: raw.file,
        sha256: raw.sha256.to_ascii_lowercase(),
        size: raw.size,
        inputs: raw.inputs,
        outputs: raw.outputs,
        preprocess,
    })
}

fn check_preprocess(name: &str, preprocess: &Preprocess) -> Result<(), String> {
    let normalisation_ok = |scale: f32, std: &[f32; 3]| {
        scale.is_finite() && scale > 0.0 && std.iter().all(|s| s.is_finite() && *s > 0.0)
    };
    match preprocess {
        Preprocess::ClipImage(p) => {
            if p.image_size == 0 || !normalisation_ok(p.pixel_scale, &p.std) {
                return Err(format!(
                    "model {name}: preprocess needs image_size > 0, pixel_scale > 0 and std > 0"
                ));
            }
        }
        Preprocess::SamEncoder(p) => {
            if p.image_size == 0
                || p.image_size % 16 != 0
                || !normalisation_ok(p.pixel_scale, &p.std)
            {
                return Err(format!(
                    "model {name}: preprocess needs image_size a positive multiple of 16, pixel_scale > 0 and std > 0"
                ));
            }
        }
        Preprocess::ClipText(p) => {
            if p.context_length < 2 {
                return Err(format!(
                    "model {name}: preprocess.context_length must be >= 2"
                ));
            }
        }
        Preprocess::SamDecoder(p) => {
            let [small, middle, large] = p.multimask_channels;
            if p.multimask_channels.iter().any(|channel| *channel > 3)
                || small == middle
                || middle == large
                || small == large
            {
                return Err(format!(
                    "model {name}: preprocess.multimask_channels must be three different decoder channels in 0..=3"
                ));
            }
        }
    }
    Ok(())
}

fn is_sha256_hex(text: &str) -> bool {
    text.len() == 64 && text.bytes().all(|byte| byte.is_ascii_hexdigit())
}

/// Model files live directly in the model directory: no paths that could leave it.
fn check_plain_file_name(file: &str) -> Result<(), &'static str> {
    let path = Path::new(file);
    let mut components = path.components();
    match (components.next(), components.next()) {
        (Some(std::path::Component::Normal(_)), None) => Ok(()),
        _ => Err("must be a plain file name inside the model directory"),
    }
}
