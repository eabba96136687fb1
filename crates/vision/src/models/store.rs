//! A model directory opened for use: every file hashed, every session opened and its signature
//! checked against the manifest and its role, the CLIP tokenizer loaded.

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use sha2::{Digest, Sha256};

use super::clip::ClipTokenizer;
use super::clip_pair::check_clip_pair;
use super::error::ModelError;
use super::manifest::{Manifest, ModelEntry, Role};
use super::recognise::{describe_signature, recognise};
use super::runtime::OrtRuntime;
use super::session::{ModelSession, actual_signature};
use super::signature::{ActualTensor, manifest_vs_role, session_vs_manifest};

/// Problems listed in one signature error; the rest are counted. The first few say what is
/// wrong; forty more only bury them.
const PROBLEMS_LISTED: usize = 3;

/// The outcome of checking one model (or the tokenizer) of a directory.
#[derive(Debug)]
pub struct CheckedFile {
    /// `clip_image` ... or `tokenizer`.
    pub role: String,
    pub name: String,
    pub file: String,
    pub result: Result<(), ModelError>,
    /// What is worth knowing but not wrong (outputs not read, optional outputs used).
    pub notes: Vec<String>,
}

/// Everything `segsplat models check` reports about a directory.
#[derive(Debug)]
pub struct DirectoryCheck {
    /// Set when the manifest itself cannot be read; nothing else was checked then.
    pub manifest_error: Option<ModelError>,
    pub files: Vec<CheckedFile>,
}

impl DirectoryCheck {
    pub fn is_ok(&self) -> bool {
        self.manifest_error.is_none() && self.files.iter().all(|file| file.result.is_ok())
    }
}

/// An opened model directory.
#[derive(Debug)]
pub struct ModelStore {
    dir: PathBuf,
    manifest: Manifest,
    runtime: Arc<OrtRuntime>,
    sessions: HashMap<Role, Arc<ModelSession>>,
    tokenizer: Option<Arc<ClipTokenizer>>,
}

impl ModelStore {
    /// Opens every model and the tokenizer; fails on the first problem, named precisely.
    pub fn open(dir: &Path, runtime: Arc<OrtRuntime>) -> Result<ModelStore, ModelError> {
        let manifest = Manifest::load(dir)?;
        let mut sessions = HashMap::new();
        for entry in &manifest.models {
            let (session, _notes) = open_model(dir, entry, &runtime)?;
            sessions.insert(entry.role, Arc::new(session));
        }
        if let (Some(image), Some(text)) = (
            sessions.get(&Role::ClipImage),
            sessions.get(&Role::ClipText),
        ) {
            check_clip_pair(image, text)?;
        }
        let tokenizer = open_tokenizer(dir, &manifest)?.map(Arc::new);
        if manifest.model(Role::ClipText).is_some() && tokenizer.is_none() {
            return Err(ModelError::Manifest {
                path: dir.join(super::manifest::MANIFEST_FILE),
                reason: "a clip_text model needs a tokenizer entry".to_string(),
            });
        }
        Ok(ModelStore {
            dir: dir.to_path_buf(),
            manifest,
            runtime,
            sessions,
            tokenizer,
        })
    }

    /// Checks every file of `dir` and reports each, without stopping at the first problem.
    pub fn check(dir: &Path, runtime: &OrtRuntime) -> DirectoryCheck {
        let manifest = match Manifest::load(dir) {
            Ok(manifest) => manifest,
            Err(error) => {
                return DirectoryCheck {
                    manifest_error: Some(error),
                    files: Vec::new(),
                };
            }
        };
        let mut files = Vec::new();
        let mut sessions = HashMap::new();
        for entry in &manifest.models {
            let (result, notes) = match open_model(dir, entry, runtime) {
                Ok((session, notes)) => {
                    sessions.insert(entry.role, session);
                    (Ok(()), notes)
                }
                Err(error) => (Err(error), Vec::new()),
            };
            files.push(CheckedFile {
                role: entry.role.to_string(),
                name: entry.name.clone(),
                file: entry.file.clone(),
                result,
                notes,
            });
        }
        if let (Some(image), Some(text)) = (
            sessions.get(&Role::ClipImage),
            sessions.get(&Role::ClipText),
        ) {
            files.push(CheckedFile {
                role: "clip pair".to_string(),
                name: format!("{} + {}", image.entry().name, text.entry().name),
                file: String::new(),
                result: check_clip_pair(image, text),
                notes: Vec::new(),
            });
        }
        if let Some(tokenizer) = &manifest.tokenizer {
            files.push(CheckedFile {
                role: "tokenizer".to_string(),
                name: "tokenizer".to_string(),
                file: tokenizer.file.clone(),
                result: open_tokenizer(dir, &manifest).map(|_| ()),
                notes: Vec::new(),
            });
        }
        DirectoryCheck {
            manifest_error: None,
            files,
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    pub fn runtime(&self) -> &Arc<OrtRuntime> {
        &self.runtime
    }

    pub fn has(&self, role: Role) -> bool {
        self.sessions.contains_key(&role)
    }

    /// The session of `role`, or [`ModelError::RoleMissing`].
    pub fn session(&self, role: Role) -> Result<Arc<ModelSession>, ModelError> {
        self.sessions
            .get(&role)
            .cloned()
            .ok_or_else(|| ModelError::RoleMissing {
                role: role.to_string(),
                dir: self.dir.clone(),
            })
    }

    pub fn tokenizer(&self) -> Result<Arc<ClipTokenizer>, ModelError> {
        self.tokenizer
            .clone()
            .ok_or_else(|| ModelError::RoleMissing {
                role: "tokenizer".to_string(),
                dir: self.dir.clone(),
            })
    }

    /// One line for logs and readiness: which roles are loaded, on what.
    pub fn summary(&self) -> String {
        let mut parts: Vec<String> = Role::ALL
            .iter()
            .filter_map(|role| self.sessions.get(role))
            .map(|session| {
                format!(
                    "{} {} ({})",
                    session.entry().role,
                    session.entry().name,
                    session.execution_provider()
                )
            })
            .collect();
        if parts.is_empty() {
            parts.push("no models".to_string());
        }
        format!(
            "{} from {}; ONNX Runtime {}",
            parts.join(", "),
            self.dir.display(),
            self.runtime.version()
        )
    }
}

/// Hash, open and signature-check one model; also returns the checks' notes.
fn open_model(
    dir: &Path,
    entry: &ModelEntry,
    runtime: &OrtRuntime,
) -> Result<(ModelSession, Vec<String>), ModelError> {
    let role = entry.role.to_string();
    let path = dir.join(&entry.file);
    verify_hash(&path, &role, &entry.file, &entry.sha256, entry.size, dir)?;
    let role_check = manifest_vs_role(entry);
    if !role_check.is_ok() {
        return Err(ModelError::Signature {
            role,
            file: entry.file.clone(),
            problems: listed(&role_check.problems, PROBLEMS_LISTED),
        });
    }
    let (session, provider) =
        runtime
            .open_session(&path)
            .map_err(|reason| ModelError::Corrupt {
                role: role.clone(),
                file: entry.file.clone(),
                reason,
            })?;
    let (inputs, outputs) = actual_signature(&session);
    let session_check = session_vs_manifest(entry, &inputs, &outputs);
    if !session_check.is_ok() {
        return Err(ModelError::Signature {
            role,
            file: entry.file.clone(),
            problems: match looks_like(entry.role, &inputs, &outputs) {
                // What the file is says most; one difference is enough to go on.
                Some(looks) => format!("{looks}{}", listed(&session_check.problems, 1)),
                None => listed(&session_check.problems, PROBLEMS_LISTED),
            },
        });
    }
    let mut notes = role_check.notes;
    notes.extend(session_check.notes);
    Ok((ModelSession::new(entry.clone(), session, provider), notes))
}

/// "this looks like a SAM decoder (...), not a sam_encoder: " when the graph plays another role.
fn looks_like(role: Role, inputs: &[ActualTensor], outputs: &[ActualTensor]) -> Option<String> {
    recognise(inputs, outputs)
        .filter(|found| found.role != role)
        .map(|found| {
            format!(
                "this looks like {} ({}), not a {role}: ",
                found.describe(),
                describe_signature(inputs, outputs)
            )
        })
}

/// The first `count` problems, and how many more there are.
fn listed(problems: &[String], count: usize) -> String {
    let mut text = problems
        .iter()
        .take(count)
        .cloned()
        .collect::<Vec<_>>()
        .join("; ");
    if problems.len() > count {
        text.push_str(&format!(" (and {} more)", problems.len() - count));
    }
    text
}

fn open_tokenizer(dir: &Path, manifest: &Manifest) -> Result<Option<ClipTokenizer>, ModelError> {
    let Some(entry) = &manifest.tokenizer else {
        return Ok(None);
    };
    let path = dir.join(&entry.file);
    verify_hash(
        &path,
        "tokenizer",
        &entry.file,
        &entry.sha256,
        entry.size,
        dir,
    )?;
    ClipTokenizer::from_file(
        &path,
        entry.context_length,
        entry.start_token,
        entry.end_token,
    )
    .map(Some)
}

fn verify_hash(
    path: &Path,
    role: &str,
    file: &str,
    expected: &str,
    expected_size: Option<u64>,
    dir: &Path,
) -> Result<(), ModelError> {
    if !path.is_file() {
        return Err(ModelError::MissingFile {
            role: role.to_string(),
            file: file.to_string(),
            dir: dir.to_path_buf(),
        });
    }
    let actual = sha256_file(path)?;
    if !actual.eq_ignore_ascii_case(expected) {
        let size = std::fs::metadata(path)
            .map(|metadata| metadata.len())
            .map_err(|source| ModelError::Read {
                path: path.to_path_buf(),
                source,
            })?;
        return Err(ModelError::HashMismatch {
            role: role.to_string(),
            file: file.to_string(),
            expected: expected.to_string(),
            actual,
            size: size_comparison(size, expected_size),
        });
    }
    Ok(())
}

fn size_comparison(size: u64, expected: Option<u64>) -> String {
    match expected {
        Some(expected) if size < expected => format!(
            "the file is {size} bytes, the manifest says {expected}: it looks truncated (an interrupted copy or download?)"
        ),
        Some(expected) if size > expected => format!(
            "the file is {size} bytes, the manifest says {expected}: a different or re-exported file"
        ),
        Some(_) => format!(
            "the size ({size} bytes) matches the manifest, so the content changed (a re-export, or corruption)"
        ),
        None => format!("the file is {size} bytes (the manifest records no size to compare)"),
    }
}

/// Hex sha256 of a file, streamed (SAM ViT-H is 2.5 GB).
pub fn sha256_file(path: &Path) -> Result<String, ModelError> {
    let read_error = |source| ModelError::Read {
        path: path.to_path_buf(),
        source,
    };
    let mut file = std::fs::File::open(path).map_err(read_error)?;
    let mut hasher = Sha256::new();
    let mut buffer = vec![0u8; 1 << 20];
    loop {
        let read = file.read(&mut buffer).map_err(read_error)?;
        if read == 0 {
            break;
        }
        hasher.update(&buffer[..read]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|byte| format!("{byte:02x}"))
        .collect())
}
