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
//! Text that spells a special token is read as open_clip reads it: `<start_of_text>` and
//! `<end_of_text>` become the start and end ids where open_clip's token pattern meets them, and
//! `<|startoftext|>` / `<|endoftext|>` are punctuation and letters like any other text. The HF
//! file's added tokens are switched off for that: left on, a typed `<|endoftext|>` would end the
//! prompt early, since the text model takes its end at the largest id.

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::LazyLock;

use regex::Regex;
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
        let text = std::fs::read_to_string(path).map_err(|error| failed(error.to_string()))?;
        let mut json: serde_json::Value =
            serde_json::from_str(&text).map_err(|error| failed(error.to_string()))?;
        // Added tokens are matched in the text before any pre-tokenizer; open_clip has none.
        json["added_tokens"] = serde_json::Value::Array(Vec::new());
        let mut tokenizer =
            Tokenizer::from_str(&json.to_string()).map_err(|error| failed(error.to_string()))?;
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
        let mut body = Vec::new();
        for piece in pieces(&cleaned) {
            match piece {
                Piece::Start => body.push(self.start_token),
                Piece::End => body.push(self.end_token),
                Piece::Text(text) => {
                    let encoding = self.tokenizer.encode(text, false).map_err(|error| {
                        ModelError::Tokenizer {
                            path: self.path.clone(),
                            reason: format!("cannot tokenize {text:?}: {error}"),
                        }
                    })?;
                    body.extend_from_slice(encoding.get_ids());
                }
            }
        }
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

/// open_clip's token pattern (`SimpleTokenizer.pat`), special tokens first; scanned like
/// Python's `findall`, it tells where a typed special token counts as one.
static OPEN_CLIP_PATTERN: LazyLock<Option<Regex>> = LazyLock::new(|| {
    Regex::new(
        r"<start_of_text>|<end_of_text>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+",
    )
    .ok()
});

#[derive(Debug, PartialEq, Eq)]
enum Piece<'a> {
    Text(&'a str),
    Start,
    End,
}

/// Splits cleaned text at the special tokens open_clip's scan meets; the text between them
/// goes to the BPE, whose pre-tokenizer splits it as open_clip's pattern would.
fn pieces(text: &str) -> Vec<Piece<'_>> {
    let Some(pattern) = OPEN_CLIP_PATTERN.as_ref() else {
        return vec![Piece::Text(text)];
    };
    let mut pieces = Vec::new();
    let mut text_start = 0;
    for found in pattern.find_iter(text) {
        let special = match found.as_str() {
            "<start_of_text>" => Piece::Start,
            "<end_of_text>" => Piece::End,
            _ => continue,
        };
        if found.start() > text_start {
            pieces.push(Piece::Text(&text[text_start..found.start()]));
        }
        pieces.push(special);
        text_start = found.end();
    }
    if text_start < text.len() {
        pieces.push(Piece::Text(&text[text_start..]));
    }
    pieces
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typed_special_tokens_split_where_open_clips_scan_meets_them() {
        assert_eq!(
            pieces("red<start_of_text>mug"),
            vec![Piece::Text("red"), Piece::Start, Piece::Text("mug")]
        );
        assert_eq!(pieces("<end_of_text>"), vec![Piece::End]);
        // Glued to punctuation the scan is inside a punctuation run: plain text.
        assert_eq!(
            pieces("x<<start_of_text>"),
            vec![Piece::Text("x<<start_of_text>")]
        );
        assert_eq!(
            pieces("the <|endoftext|> mug"),
            vec![Piece::Text("the <|endoftext|> mug")]
        );
    }
}
