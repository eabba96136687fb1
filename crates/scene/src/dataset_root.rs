//! Finding the dataset inside an unpacked upload, which may be wrapped in one folder.

use std::fs;
use std::path::{Path, PathBuf};

use super::{SceneError, blender, colmap, nerfies, nerfstudio, neu3d};

/// `root` when it holds a dataset; otherwise its single visible sub-folder when it has exactly
/// one (zipping a folder wraps everything in it). Only one level is looked through.
pub fn resolve_dataset_root(root: &Path) -> Result<PathBuf, SceneError> {
    if holds_dataset(root) {
        return Ok(root.to_path_buf());
    }
    let entries = visible_entries(root)?;
    match entries.as_slice() {
        [only] if only.is_dir() && holds_dataset(only) => Ok(only.clone()),
        _ => Ok(root.to_path_buf()),
    }
}

fn holds_dataset(dir: &Path) -> bool {
    colmap::find_model(dir).is_some()
        || dir.join(nerfstudio::TRANSFORMS_FILE).is_file()
        || dir.join(blender::TRAIN_TRANSFORMS_FILE).is_file()
        || nerfies::is_nerfies(dir)
        || neu3d::is_neu3d(dir)
}

/// Entries of `dir` except hidden ones and macOS archive debris.
fn visible_entries(dir: &Path) -> Result<Vec<PathBuf>, SceneError> {
    let read_dir = fs::read_dir(dir).map_err(|source| SceneError::Io {
        file: dir.display().to_string(),
        source,
    })?;
    let mut entries = Vec::new();
    for entry in read_dir {
        let entry = entry.map_err(|source| SceneError::Io {
            file: dir.display().to_string(),
            source,
        })?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') || name == "__MACOSX" {
            continue;
        }
        entries.push(entry.path());
    }
    entries.sort();
    Ok(entries)
}

/// A short listing for "no dataset found" errors: " (found: a/, b.txt)".
pub fn describe_contents(dir: &Path) -> String {
    const SHOWN: usize = 10;
    let Ok(entries) = visible_entries(dir) else {
        return String::new();
    };
    if entries.is_empty() {
        return " (the archive is empty)".to_string();
    }
    let mut names: Vec<String> = entries
        .iter()
        .take(SHOWN)
        .map(|path| {
            let name = path
                .file_name()
                .map(|name| name.to_string_lossy().into_owned())
                .unwrap_or_default();
            if path.is_dir() {
                format!("{name}/")
            } else {
                name
            }
        })
        .collect();
    if entries.len() > SHOWN {
        names.push(format!("and {} more", entries.len() - SHOWN));
    }
    format!(" (found: {})", names.join(", "))
}
