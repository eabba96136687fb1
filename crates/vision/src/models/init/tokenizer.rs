//! The manifest's tokenizer entry: which file of the folder is the CLIP text model's tokenizer,
//! and the ids of the tokens that frame every text.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::{Value, json};

use super::{DEFAULT_CONTEXT_LENGTH, Graph, file_size, fixed_dim, init_error};
use crate::models::error::ModelError;
use crate::models::manifest::Role;
use crate::models::store::sha256_file;

const TOKENIZER_FILE: &str = "tokenizer.json";
const START_TOKEN: &str = "<|startoftext|>";
const END_TOKEN: &str = "<|endoftext|>";

/// The tokenizer file of the folder: the one named, else `tokenizer.json`, else the folder's
/// only `*tokenizer*.json` (exports name it `clip_tokenizer.json` and the like). `Ok(None)`
/// when there is none; an error when the choice is ambiguous or the named file is elsewhere.
fn find_tokenizer(dir: &Path, named: Option<&Path>) -> Result<Option<String>, ModelError> {
    if let Some(named) = named {
        let name = named
            .file_name()
            .and_then(|name| name.to_str())
            .map(str::to_string);
        return match name {
            Some(name) if dir.join(&name).is_file() => Ok(Some(name)),
            _ => Err(init_error(
                dir,
                format!(
                    "--tokenizer {}: no such file in {} (the tokenizer must sit beside the models)",
                    named.display(),
                    dir.display()
                ),
            )),
        };
    }
    if dir.join(TOKENIZER_FILE).is_file() {
        return Ok(Some(TOKENIZER_FILE.to_string()));
    }
    let mut candidates: Vec<String> = std::fs::read_dir(dir)
        .map_err(|error| init_error(dir, format!("cannot list the folder: {error}")))?
        .filter_map(|entry| entry.ok()?.file_name().into_string().ok())
        .filter(|name| {
            let lower = name.to_lowercase();
            lower.contains("tokenizer") && lower.ends_with(".json")
        })
        .collect();
    candidates.sort();
    match candidates.len() {
        0 => Ok(None),
        1 => Ok(candidates.pop()),
        _ => Err(init_error(
            dir,
            format!(
                "several tokenizer files ({}); name the CLIP text model's with --tokenizer",
                candidates.join(", ")
            ),
        )),
    }
}

/// The tokenizer entry when the folder has a tokenizer; a CLIP text model needs one.
pub(super) fn tokenizer_entry(
    dir: &Path,
    by_role: &BTreeMap<&'static str, Graph>,
    named: Option<&Path>,
) -> Result<Option<Value>, ModelError> {
    let text_model = by_role.get(Role::ClipText.as_str());
    let Some(file) = find_tokenizer(dir, named)? else {
        return match text_model {
            Some(graph) => Err(init_error(
                dir,
                format!(
                    "{} is a CLIP text model but no tokenizer file is there ({TOKENIZER_FILE} \
                     or one *tokenizer*.json: the HuggingFace tokenizers file of the model's \
                     BPE, which scripts/export_models.py writes; --tokenizer names another)",
                    graph.file
                ),
            )),
            None => Ok(None),
        };
    };
    let path = dir.join(&file);
    let tokenizer =
        tokenizers::Tokenizer::from_file(&path).map_err(|error| ModelError::Tokenizer {
            path: path.clone(),
            reason: error.to_string(),
        })?;
    let id = |token: &str| {
        tokenizer
            .token_to_id(token)
            .ok_or_else(|| ModelError::Tokenizer {
                path: path.clone(),
                reason: format!("has no {token} token; CLIP's BPE frames every text with it"),
            })
    };
    let context_length = text_model
        .and_then(|graph| fixed_dim(&graph.inputs, "input_ids", 1))
        .unwrap_or(DEFAULT_CONTEXT_LENGTH as i64);
    Ok(Some(json!({
        "file": file,
        "sha256": sha256_file(&path)?,
        "size": file_size(&path)?,
        "context_length": context_length,
        "start_token": id(START_TOKEN)?,
        "end_token": id(END_TOKEN)?,
    })))
}
