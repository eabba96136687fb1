//! The blocking half of a scene upload: unpack the archive, detect and validate the dataset, and
//! copy its files into the blob store. On any error the caller removes what was written.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::store::process_tag::process_tag;
use crate::store::{BlobError, BlobStore};
use segsplat_scene::IGNORED_FILES_LISTED;
use segsplat_scene::used_files::used_files;
use segsplat_scene::{
    ArchiveError, InputErrorClass, LoadOptions, PixelLimits, SceneError, SceneSummary,
    UnpackLimits, load_scene, unpack_archive, validate_scene_within,
};

#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    #[error(transparent)]
    Archive(#[from] ArchiveError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("storing the scene failed: {0}")]
    Blob(#[from] BlobError),
    #[error("{context}: {source}")]
    Io {
        context: String,
        #[source]
        source: std::io::Error,
    },
}

impl IngestError {
    pub fn class(&self) -> InputErrorClass {
        match self {
            IngestError::Archive(error) => error.class(),
            IngestError::Scene(error) => error.class(),
            IngestError::Blob(_) | IngestError::Io { .. } => InputErrorClass::Internal,
        }
    }

    /// What the client is told: the error, and for an archive over a limit the setting that
    /// sets it (the scene crate knows the limits, not the service's names for them).
    pub fn client_message(&self) -> String {
        let setting = match self {
            IngestError::Archive(
                ArchiveError::TooManyBytes { .. } | ArchiveError::DeclaresTooManyBytes { .. },
            ) => "limits.max_unpacked_bytes",
            IngestError::Archive(
                ArchiveError::TooManyFiles { .. } | ArchiveError::DeclaresTooManyEntries { .. },
            ) => "limits.max_files",
            _ => return self.to_string(),
        };
        format!("{self} ({setting})")
    }
}

pub struct IngestRequest {
    pub archive: PathBuf,
    /// Unpacking happens in a temporary folder here.
    pub scratch_dir: PathBuf,
    pub limits: UnpackLimits,
    pub load_options: LoadOptions,
    pub pixel_limits: PixelLimits,
    pub blobs: Arc<dyn BlobStore>,
    /// Where the files go: `{blob_prefix}/files/<relative path>`.
    pub blob_prefix: String,
}

/// Unpacks, validates and stores. On error, files may have reached the blob store under
/// `blob_prefix`: the caller removes them, or records their removal when the store is down
/// (`store::blob_deletions::remove_or_record`).
pub fn ingest_scene(request: &IngestRequest) -> Result<SceneSummary, IngestError> {
    let unpack_dir = tempfile::Builder::new()
        // Named after this process, so a restart's sweep knows when its writer is gone.
        .prefix(&format!("unpack-{}-", process_tag()))
        .tempdir_in(&request.scratch_dir)
        .map_err(|source| IngestError::Io {
            context: format!(
                "cannot create a folder to unpack into under {}",
                request.scratch_dir.display()
            ),
            source,
        })?;
    unpack_archive(&request.archive, unpack_dir.path(), &request.limits)?;
    // The loader looks through a single wrapping folder; `scene.root` is the dataset itself.
    let scene = load_scene(unpack_dir.path(), &request.load_options)?;
    let mut summary = validate_scene_within(&scene, &request.pixel_limits)?;
    for lens in &summary.undistorted {
        tracing::info!(
            lens = %segsplat_scene::distortion::describe_lens(lens),
            "upload has lens distortion; its frames are undistorted to pinhole cameras"
        );
    }
    let used = used_files(&scene);
    store_tree(&scene.root, &scene.root, &used, request, &mut summary)?;
    Ok(summary)
}

/// Stores the files of `used` under `dir` and counts the rest into `summary` as ignored.
fn store_tree(
    root: &Path,
    dir: &Path,
    used: &BTreeSet<PathBuf>,
    request: &IngestRequest,
    summary: &mut SceneSummary,
) -> Result<(), IngestError> {
    let io_error = |source| IngestError::Io {
        context: format!("cannot read unpacked folder {}", dir.display()),
        source,
    };
    for entry in std::fs::read_dir(dir).map_err(io_error)? {
        let entry = entry.map_err(io_error)?;
        let path = entry.path();
        let kind = entry.file_type().map_err(io_error)?;
        if kind.is_dir() {
            store_tree(root, &path, used, request, summary)?;
        } else if kind.is_file() {
            let relative_path = path.strip_prefix(root).unwrap_or(&path);
            if !used.contains(relative_path) {
                summary.ignored_file_count += 1;
                if summary.ignored_files.len() < IGNORED_FILES_LISTED {
                    summary
                        .ignored_files
                        .push(relative_path.to_string_lossy().into_owned());
                }
                continue;
            }
            let relative: Vec<String> = relative_path
                .components()
                .map(|component| component.as_os_str().to_string_lossy().into_owned())
                .collect();
            let key = format!("{}/files/{}", request.blob_prefix, relative.join("/"));
            request.blobs.put_file(&key, &path)?;
        }
    }
    Ok(())
}
