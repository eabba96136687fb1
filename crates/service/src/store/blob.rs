//! Blob storage for scene files, checkpoints and results, addressed by `/`-separated keys.
//!
//! The methods block (plain file I/O here, an HTTP client for an object store later); call them
//! from blocking contexts (`spawn_blocking`, job steps). Prefixes are whole key segments:
//! `scenes/abc` covers `scenes/abc/x` but not `scenes/abcd`.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Marks in-progress writes; never part of a valid key, skipped by listings.
pub const TEMP_MARKER: &str = ".segsplat-tmp-";

#[derive(Debug, thiserror::Error)]
pub enum BlobError {
    #[error("invalid blob key {key:?}: {reason}")]
    InvalidKey { key: String, reason: &'static str },
    #[error("blob {key} does not exist")]
    NotFound { key: String },
    /// The object store cannot be reached or refuses the request; the service answers 503.
    #[error("the blob store is unavailable ({key}): {reason}")]
    Unavailable { key: String, reason: String },
    #[error("blob {key}: {source}")]
    Io {
        key: String,
        #[source]
        source: std::io::Error,
    },
}

pub trait BlobStore: Send + Sync + std::fmt::Debug {
    /// Stores `bytes` under `key`, replacing any previous value atomically.
    fn put_bytes(&self, key: &str, bytes: &[u8]) -> Result<(), BlobError>;
    /// Stores the contents of the file at `source` under `key`, atomically.
    fn put_file(&self, key: &str, source: &Path) -> Result<(), BlobError>;
    fn get_bytes(&self, key: &str) -> Result<Vec<u8>, BlobError>;
    /// Copies the blob to `destination` (parent folders created).
    fn get_to_path(&self, key: &str, destination: &Path) -> Result<(), BlobError>;
    fn exists(&self, key: &str) -> Result<bool, BlobError>;
    /// Every key under `prefix`, sorted.
    fn list_prefix(&self, prefix: &str) -> Result<Vec<String>, BlobError>;
    /// Removes every key under `prefix`; returns how many were removed.
    fn delete_prefix(&self, prefix: &str) -> Result<u64, BlobError>;
    /// Where the key (or prefix) lives on the local filesystem, when the store is local; lets
    /// workers read scene files in place instead of copying them.
    fn local_path(&self, _key: &str) -> Option<PathBuf> {
        None
    }
}

/// A directory on the local filesystem. Every write goes to a temporary file in the target
/// folder, is fsynced, renamed over the final name and the folder fsynced: a crash leaves either
/// the old blob, the new one, or a temporary file that listings ignore, never a half file under
/// the final name.
#[derive(Debug, Clone)]
pub struct LocalBlobStore {
    root: PathBuf,
}

impl LocalBlobStore {
    pub fn open(root: &Path) -> Result<Self, BlobError> {
        std::fs::create_dir_all(root).map_err(|source| BlobError::Io {
            key: root.display().to_string(),
            source,
        })?;
        Ok(Self {
            root: root.to_path_buf(),
        })
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    fn path_of(&self, key: &str) -> Result<PathBuf, BlobError> {
        validate_key(key)?;
        Ok(self.root.join(key))
    }

    /// Writes via `write_contents` into a temporary sibling of `key`'s path, then publishes it.
    fn write_atomically(
        &self,
        key: &str,
        write_contents: impl FnOnce(&mut File) -> std::io::Result<()>,
    ) -> Result<(), BlobError> {
        let path = self.path_of(key)?;
        let io_error = |source| BlobError::Io {
            key: key.to_string(),
            source,
        };
        let parent = path.parent().unwrap_or(&self.root).to_path_buf();
        std::fs::create_dir_all(&parent).map_err(io_error)?;
        let file_name = path
            .file_name()
            .map(|name| name.to_string_lossy().into_owned())
            .unwrap_or_default();
        // The writer's process tag lets a sweep tell a killed writer's leftovers from live ones.
        let temp_path = parent.join(format!(
            ".{file_name}{TEMP_MARKER}{}-{}",
            super::process_tag::process_tag(),
            uuid::Uuid::new_v4().simple()
        ));
        let result = (|| {
            let mut file = File::create(&temp_path)?;
            write_contents(&mut file)?;
            file.flush()?;
            file.sync_all()?;
            drop(file);
            std::fs::rename(&temp_path, &path)?;
            sync_dir(&parent)
        })();
        if result.is_err() {
            let _ = std::fs::remove_file(&temp_path);
        }
        result.map_err(io_error)
    }
}

impl BlobStore for LocalBlobStore {
    fn put_bytes(&self, key: &str, bytes: &[u8]) -> Result<(), BlobError> {
        self.write_atomically(key, |file| file.write_all(bytes))
    }

    fn put_file(&self, key: &str, source: &Path) -> Result<(), BlobError> {
        self.write_atomically(key, |file| {
            let mut input = File::open(source)?;
            std::io::copy(&mut input, file).map(|_| ())
        })
    }

    fn get_bytes(&self, key: &str) -> Result<Vec<u8>, BlobError> {
        let path = self.path_of(key)?;
        std::fs::read(&path).map_err(|source| not_found_or_io(key, source))
    }

    fn get_to_path(&self, key: &str, destination: &Path) -> Result<(), BlobError> {
        let path = self.path_of(key)?;
        if let Some(parent) = destination.parent() {
            std::fs::create_dir_all(parent).map_err(|source| BlobError::Io {
                key: key.to_string(),
                source,
            })?;
        }
        std::fs::copy(&path, destination)
            .map(|_| ())
            .map_err(|source| not_found_or_io(key, source))
    }

    fn exists(&self, key: &str) -> Result<bool, BlobError> {
        Ok(self.path_of(key)?.is_file())
    }

    fn list_prefix(&self, prefix: &str) -> Result<Vec<String>, BlobError> {
        let start = if prefix.trim_end_matches('/').is_empty() {
            self.root.clone()
        } else {
            self.path_of(prefix.trim_end_matches('/'))?
        };
        let mut keys = Vec::new();
        if start.is_file() {
            keys.push(prefix.trim_end_matches('/').to_string());
        } else if start.is_dir() {
            collect_keys(&self.root, &start, &mut keys).map_err(|source| BlobError::Io {
                key: prefix.to_string(),
                source,
            })?;
        }
        keys.sort();
        Ok(keys)
    }

    fn delete_prefix(&self, prefix: &str) -> Result<u64, BlobError> {
        let trimmed = prefix.trim_end_matches('/');
        let path = self.path_of(trimmed)?;
        let io_error = |source| BlobError::Io {
            key: prefix.to_string(),
            source,
        };
        if path.is_file() {
            std::fs::remove_file(&path).map_err(io_error)?;
            return Ok(1);
        }
        if !path.is_dir() {
            return Ok(0);
        }
        let count = self.list_prefix(trimmed)?.len() as u64;
        std::fs::remove_dir_all(&path).map_err(io_error)?;
        if let Some(parent) = path.parent() {
            sync_dir(parent).map_err(io_error)?;
        }
        Ok(count)
    }

    fn local_path(&self, key: &str) -> Option<PathBuf> {
        self.path_of(key.trim_end_matches('/')).ok()
    }
}

pub(crate) fn validate_key(key: &str) -> Result<(), BlobError> {
    let invalid = |reason| {
        Err(BlobError::InvalidKey {
            key: key.to_string(),
            reason,
        })
    };
    if key.is_empty() {
        return invalid("empty");
    }
    if key.contains('\\') || key.contains('\0') {
        return invalid("contains a backslash or NUL");
    }
    if key.contains(TEMP_MARKER) {
        return invalid("contains the reserved temporary-file marker");
    }
    for segment in key.split('/') {
        if segment.is_empty() || segment == "." || segment == ".." {
            return invalid("segments must be non-empty and not . or ..");
        }
    }
    Ok(())
}

fn collect_keys(root: &Path, dir: &Path, keys: &mut Vec<String>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let path = entry.path();
        let file_type = entry.file_type()?;
        if file_type.is_dir() {
            collect_keys(root, &path, keys)?;
        } else if file_type.is_file() {
            let name = entry.file_name();
            if name.to_string_lossy().contains(TEMP_MARKER) {
                continue;
            }
            if let Ok(relative) = path.strip_prefix(root) {
                let key: Vec<String> = relative
                    .components()
                    .map(|component| component.as_os_str().to_string_lossy().into_owned())
                    .collect();
                keys.push(key.join("/"));
            }
        }
    }
    Ok(())
}

pub(crate) fn not_found_or_io(key: &str, source: std::io::Error) -> BlobError {
    if source.kind() == std::io::ErrorKind::NotFound {
        BlobError::NotFound {
            key: key.to_string(),
        }
    } else {
        BlobError::Io {
            key: key.to_string(),
            source,
        }
    }
}

/// Makes a rename durable by syncing the folder that holds it (a no-op where folders cannot be
/// opened, e.g. Windows).
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    match File::open(dir) {
        Ok(handle) => handle.sync_all().or(Ok(())),
        Err(_) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_are_atomic_and_listed_by_prefix() {
        let dir = tempfile::tempdir().unwrap();
        let store = LocalBlobStore::open(dir.path()).unwrap();
        store.put_bytes("scenes/a/files/x.txt", b"one").unwrap();
        store.put_bytes("scenes/a/files/sub/y.txt", b"two").unwrap();
        store.put_bytes("scenes/ab/z.txt", b"three").unwrap();
        store
            .put_bytes("scenes/a/files/x.txt", b"replaced")
            .unwrap();
        // A leftover temporary file from a crashed write is not a blob.
        std::fs::write(
            dir.path().join("scenes/a/files/.x.txt.segsplat-tmp-123"),
            b"half",
        )
        .unwrap();
        assert_eq!(
            store.get_bytes("scenes/a/files/x.txt").unwrap(),
            b"replaced"
        );
        assert_eq!(
            store.list_prefix("scenes/a").unwrap(),
            vec!["scenes/a/files/sub/y.txt", "scenes/a/files/x.txt"]
        );
        assert_eq!(store.delete_prefix("scenes/a/").unwrap(), 2);
        assert!(!store.exists("scenes/a/files/x.txt").unwrap());
        assert!(store.exists("scenes/ab/z.txt").unwrap());
        assert!(matches!(
            store.get_bytes("scenes/a/files/x.txt"),
            Err(BlobError::NotFound { .. })
        ));
    }

    #[test]
    fn rejects_escaping_keys() {
        let dir = tempfile::tempdir().unwrap();
        let store = LocalBlobStore::open(dir.path()).unwrap();
        for key in ["../x", "a//b", "/abs", "a/./b", ""] {
            assert!(
                matches!(
                    store.put_bytes(key, b"x"),
                    Err(BlobError::InvalidKey { .. })
                ),
                "{key}"
            );
        }
    }
}
