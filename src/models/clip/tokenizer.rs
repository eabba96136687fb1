//! CLIP's byte-level BPE tokenizer from a HuggingFace `tokenizer.json`, with open_clip's text
//! clean-up and framing, so that a prompt gets the ids `open_clip.get_tokenizer(...)` gives it.
//!
//! The clean-up (`text_clean`: ftfy's fixes, HTML entities, whitespace, lower case) replaces the
//! JSON's normalizer: open_clip normalises nothing after its clean-up, and the usual CLIP normalizer
//! (NFC, whitespace, lower case) run again would, for instance, compose an accent that
//! `html.unescape` produced as a combining mark. The framing is done here too, not by the JSON's
//! post-processor, so a tokenizer.json with other padding or truncation settings still gives
//! open_clip's ids: `<|startoftext|>`, at most `context_length - 2` BPE ids, `<|endoftext|>`, zeros
//! to `context_length`.
//!
//! Known difference: text that spells a special token. open_clip reads `<start_of_text>` and
//! `<end_of_text>` in a prompt as its start and end ids and `<|endoftext|>` as punctuation and
//! letters; the HF tokenizer reads its added tokens `<|startoftext|>` and `<|endoftext|>` as the
//! ids and the other two as punctuation and letters.

use std::path::{Path, PathBuf};

use tokenizers::Tokenizer;
use tokenizers::normalizers::NormalizerWrapper;

use super::text_clean::clean_text;
use crate::models::error::ModelError;

pub struct ClipTokenizer {
    tokenizer: Tokenizer,
    path: PathBuf,
    context_length: usize,
    start_token: u32,
    end_token: u32,
}

impl std::fmt::Debug for ClipTokenizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClipTokenizer")
            .field("path", &self.path)
            .field("context_length", &self.context_length)
            .finish()
    }
}

impl ClipTokenizer {
    pub fn from_file(
        path: &Path,
        context_length: usize,
        start_token: u32,
        end_token: u32,
    ) -> Result<ClipTokenizer, ModelError> {
        let failed = |reason: String| ModelError::Tokenizer {
            path: path.to_path_buf(),
            reason,
        };
        if context_length < 2 {
            return Err(failed("context_length must be >= 2".to_string()));
        }
        let mut tokenizer =
            Tokenizer::from_file(path).map_err(|error| failed(error.to_string()))?;
        tokenizer
            .with_truncation(None)
            .map_err(|error| failed(error.to_string()))?;
        tokenizer.with_padding(None);
        tokenizer.with_normalizer(None::<NormalizerWrapper>);
        Ok(ClipTokenizer {
            tokenizer,
            path: path.to_path_buf(),
            context_length,
            start_token,
            end_token,
        })
    }

    pub fn context_length(&self) -> usize {
        self.context_length
    }

    /// open_clip's ids for one text (cleaned first): always `context_length` long.
    pub fn encode(&self, text: &str) -> Result<Vec<i64>, ModelError> {
        let cleaned = clean_text(text);
        let encoding = self
            .tokenizer
            .encode(cleaned.as_str(), false)
            .map_err(|error| ModelError::Tokenizer {
                path: self.path.clone(),
                reason: format!("cannot tokenize {text:?}: {error}"),
            })?;
        let body = encoding.get_ids();
        let kept = body.len().min(self.context_length - 2);
        let mut ids = Vec::with_capacity(self.context_length);
        ids.push(i64::from(self.start_token));
        ids.extend(body[..kept].iter().map(|id| i64::from(*id)));
        ids.push(i64::from(self.end_token));
        ids.resize(self.context_length, 0);
        Ok(ids)
    }

    /// Ids for several texts, concatenated row by row (`texts.len() x context_length`).
    pub fn encode_batch(&self, texts: &[&str]) -> Result<Vec<i64>, ModelError> {
        let mut ids = Vec::with_capacity(texts.len() * self.context_length);
        for text in texts {
            ids.extend(self.encode(text)?);
        }
        Ok(ids)
    }
}
