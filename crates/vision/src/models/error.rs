//! The one error type of `models`: every failure names the model, the file and what is wrong.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error(
        "ONNX Runtime library not found: {tried}. Set models.ort_library (SEGSPLAT_MODELS__ORT_LIBRARY) or ORT_DYLIB_PATH, or `pip install onnxruntime`"
    )]
    LibraryNotFound { tried: String },
    #[error("cannot load the ONNX Runtime library {path}: {reason}")]
    LibraryLoad { path: PathBuf, reason: String },
    #[error("ONNX Runtime at {path} is version {found}; segsplat needs {needed} or newer")]
    LibraryTooOld {
        path: PathBuf,
        found: String,
        needed: String,
    },
    #[error("ONNX Runtime: {0}")]
    Runtime(String),
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("manifest {path}: {reason}")]
    Manifest { path: PathBuf, reason: String },
    #[error("{role} {file}: file not found in {dir}")]
    MissingFile {
        role: String,
        file: String,
        dir: PathBuf,
    },
    #[error("{role} {file}: sha256 is {actual}, manifest says {expected}; {size}")]
    HashMismatch {
        role: String,
        file: String,
        expected: String,
        actual: String,
        /// The file's size against the manifest's, which tells a truncated copy from another file.
        size: String,
    },
    #[error("{role} {file}: ONNX Runtime cannot open it: {reason}")]
    Corrupt {
        role: String,
        file: String,
        reason: String,
    },
    #[error("{role} {file}: {problems}")]
    Signature {
        role: String,
        file: String,
        problems: String,
    },
    #[error("no {role} model in the model directory {dir}")]
    RoleMissing { role: String, dir: PathBuf },
    #[error("tokenizer {path}: {reason}")]
    Tokenizer { path: PathBuf, reason: String },
    #[error("{model}: inference failed: {reason}")]
    Inference { model: String, reason: String },
    #[error("{model}: unexpected output: {reason}")]
    Output { model: String, reason: String },
    #[error("invalid input: {0}")]
    Input(String),
    /// Two models of one directory that cannot work together.
    #[error("{0}")]
    Pair(String),
}
