//! CLIP's byte-level BPE tokenizer from a HuggingFace `tokenizer.json`, with open_clip's framing:
//! `<|startoftext|>`, at most `context_length - 2` BPE ids, `<|endoftext|>`, zeros to
//! `context_length`. The framing is done here, not by the JSON's post-processor, so a
//! tokenizer.json with other padding or truncation settings still gives open_clip's ids.
//! open_clip's text cleaning (ftfy, HTML unescape) is not reproduced.

use std::path::{Path, PathBuf};

use tokenizers::Tokenizer;

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

    /// open_clip's ids for one text: always `context_length` long.
    pub fn encode(&self, text: &str) -> Result<Vec<i64>, ModelError> {
        let encoding =
            self.tokenizer
                .encode(text, false)
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
