//! Reclaiming what killed processes leave behind: partial uploads (`tmp/upload-*`), unpack
//! folders (`tmp/unpack-*`), per-attempt job folders (`tmp/job-<id>-<attempt>`), partial blob
//! writes (`*.segsplat-tmp-*` anywhere under `blobs/`) and partial scene fetches of the workers'
//! scene cache (`cache/scenes/.*.segsplat-tmp-*`).
//!
//! Never what a live writer still uses. Uploads, unpack folders and blob temp files carry their
//! writer's process tag (`{host}-pid{pid}`): they go at once when that process on this host has
//! exited, otherwise (another host sharing the store, or a name from an older version) only when
//! untouched for `storage.temp_max_age_secs`. A job folder goes when its job is no longer running
//! that attempt (the database says who works on what).

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use crate::store::blob::TEMP_MARKER;
use crate::store::jobs::JobState;
use crate::store::process_tag::tagged_by_a_stopped_local_process;
use crate::store::{Caller, Database};

/// Where to look and how old an unattributable leftover must be.
#[derive(Debug, Clone)]
pub struct SweepPlaces {
    pub scratch_dir: PathBuf,
    pub blob_dir: PathBuf,
    /// Workers' scene copies (`jobs::scene_cache`).
    pub scene_cache_dir: PathBuf,
    pub max_age: Duration,
}

/// Removes leftovers; returns what was removed (errors are logged, never fatal).
pub async fn sweep_leftovers(places: &SweepPlaces, database: &Database) -> Vec<PathBuf> {
    let scan_places = places.clone();
    let scanned = tokio::task::spawn_blocking(move || scan(&scan_places)).await;
    let (mut stale, job_dirs) = match scanned {
        Ok(found) => found,
        Err(error) => {
            tracing::warn!(%error, "scanning for leftover temporary files crashed");
            return Vec::new();
        }
    };
    for (path, job_id, attempt) in job_dirs {
        let live = match database.get_job(&job_id, &Caller::system()).await {
            Ok(Some(job)) => job.state == JobState::Running && job.attempts == attempt,
            Ok(None) => false,
            // Unknown: leave it for the next sweep.
            Err(_) => true,
        };
        if !live {
            stale.push(path);
        }
    }
    let removed = tokio::task::spawn_blocking(move || {
        stale
            .into_iter()
            .filter(|path| match remove(path) {
                Ok(()) => true,
                Err(error) => {
                    tracing::warn!(%error, path = %path.display(),
                        "cannot remove a leftover temporary file");
                    false
                }
            })
            .collect::<Vec<_>>()
    })
    .await
    .unwrap_or_default();
    for path in &removed {
        tracing::info!(path = %path.display(), "removed a leftover of a stopped process");
    }
    removed
}

/// (stale paths, job folders as (path, job id, attempt) to check against the database).
fn scan(places: &SweepPlaces) -> (Vec<PathBuf>, Vec<(PathBuf, String, u32)>) {
    let mut stale = Vec::new();
    let mut job_dirs = Vec::new();
    if let Ok(entries) = std::fs::read_dir(&places.scratch_dir) {
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some(rest) = name.strip_prefix("job-") {
                if let Some((job_id, attempt)) = rest.rsplit_once('-')
                    && let Ok(attempt) = attempt.parse()
                {
                    job_dirs.push((path, job_id.to_string(), attempt));
                }
            } else if let Some(tagged) = name
                .strip_prefix("upload-")
                .or_else(|| name.strip_prefix("unpack-"))
                .or_else(|| name.strip_prefix("download-"))
                && is_stale(&path, tagged, places.max_age)
            {
                stale.push(path);
            }
        }
    }
    collect_blob_temps(&places.blob_dir, places.max_age, &mut stale);
    if let Ok(entries) = std::fs::read_dir(&places.scene_cache_dir) {
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some((_, tagged)) = name.split_once(TEMP_MARKER)
                && is_stale(&entry.path(), tagged, places.max_age)
            {
                stale.push(entry.path());
            }
        }
    }
    (stale, job_dirs)
}

fn collect_blob_temps(dir: &Path, max_age: Duration, stale: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let Ok(kind) = entry.file_type() else {
            continue;
        };
        if kind.is_dir() {
            collect_blob_temps(&path, max_age, stale);
        } else if kind.is_file() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some((_, tagged)) = name.split_once(TEMP_MARKER)
                && is_stale(&path, tagged, max_age)
            {
                stale.push(path);
            }
        }
    }
}

/// Its writer (named by `tagged`) has exited, or it has not been modified for `max_age`.
fn is_stale(path: &Path, tagged: &str, max_age: Duration) -> bool {
    if tagged_by_a_stopped_local_process(tagged) {
        return true;
    }
    let modified = std::fs::symlink_metadata(path).and_then(|meta| meta.modified());
    modified.is_ok_and(|modified| {
        SystemTime::now()
            .duration_since(modified)
            .is_ok_and(|age| age > max_age)
    })
}

fn remove(path: &Path) -> std::io::Result<()> {
    let result = match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.is_dir() => std::fs::remove_dir_all(path),
        Ok(_) => std::fs::remove_file(path),
        Err(error) => Err(error),
    };
    match result {
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => Ok(()),
        other => other,
    }
}
