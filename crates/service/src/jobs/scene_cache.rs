//! Workers' local copies of scene files when the blobs live in an object store: a scene is
//! fetched once, kept for the next job on it, and the least recently used scenes are removed once
//! the copies pass their size budget. A scene a running job of this process uses is never removed.
//!
//! A copy is complete or absent: files are fetched into a temporary folder, which is renamed into
//! place only once whole, so a worker killed mid-fetch leaves a folder the next fetch ignores and
//! the leftover sweep (`jobs::temp_sweep`) removes once that process is gone.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use super::JobFailure;
use crate::store::BlobStore;
use crate::store::blob::TEMP_MARKER;
use crate::store::process_tag::process_tag;

/// Written last into a complete copy; its modification time is the copy's last use.
const COMPLETE: &str = ".complete";

#[derive(Debug)]
pub struct SceneFileCache {
    root: PathBuf,
    budget_bytes: u64,
    /// Scenes running jobs of this process use, with how many.
    in_use: Mutex<HashMap<String, usize>>,
}

/// A scene's local folder, held for one job; the copy is not evicted while held.
#[derive(Debug)]
pub struct CachedScene {
    pub dir: PathBuf,
    scene_id: String,
    cache: Arc<SceneFileCache>,
}

impl Drop for CachedScene {
    fn drop(&mut self) {
        self.cache.release(&self.scene_id);
    }
}

impl SceneFileCache {
    pub fn new(root: PathBuf, budget_bytes: u64) -> Self {
        Self {
            root,
            budget_bytes,
            in_use: Mutex::new(HashMap::new()),
        }
    }

    /// The scene's files on local disk, fetched from `blobs` (`scenes/{id}/files/...`) unless a
    /// complete copy is here already. Blocking. A store that cannot be reached is
    /// [`JobFailure::Unavailable`] (the worker waits for it); local trouble is retryable.
    pub fn checkout(
        self: &Arc<Self>,
        blobs: &dyn BlobStore,
        scene_id: &str,
    ) -> Result<CachedScene, JobFailure> {
        self.hold(scene_id);
        let held = CachedScene {
            dir: self.root.join(scene_id),
            scene_id: scene_id.to_string(),
            cache: self.clone(),
        };
        let marker = held.dir.join(COMPLETE);
        if marker.is_file() {
            touch(&marker);
            return Ok(held);
        }
        self.fetch(blobs, scene_id, &held.dir)?;
        self.evict_over_budget();
        Ok(held)
    }

    fn fetch(&self, blobs: &dyn BlobStore, scene_id: &str, dir: &Path) -> Result<(), JobFailure> {
        let local = |message: String| JobFailure::Retryable(message);
        let prefix = format!("scenes/{scene_id}/files");
        // Named after this process, so a sweep knows when its fetcher is gone.
        let temp = self.root.join(format!(
            ".{scene_id}{TEMP_MARKER}{}-{}",
            process_tag(),
            uuid::Uuid::new_v4().simple()
        ));
        let result = (|| {
            std::fs::create_dir_all(&temp)
                .map_err(|error| local(format!("cannot create {}: {error}", temp.display())))?;
            for key in blobs.list_prefix(&prefix)? {
                let relative = key
                    .strip_prefix(&prefix)
                    .unwrap_or(&key)
                    .trim_start_matches('/');
                blobs.get_to_path(&key, &temp.join(relative))?;
            }
            std::fs::write(temp.join(COMPLETE), b"")
                .map_err(|error| local(format!("cannot finish {}: {error}", temp.display())))?;
            match std::fs::rename(&temp, dir) {
                Ok(()) => Ok(()),
                // Another worker of this process finished the same scene first.
                Err(_) if dir.join(COMPLETE).is_file() => Ok(()),
                Err(error) => Err(local(format!("cannot place {}: {error}", dir.display()))),
            }
        })();
        let _ = std::fs::remove_dir_all(&temp);
        result
    }

    fn hold(&self, scene_id: &str) {
        if let Ok(mut in_use) = self.in_use.lock() {
            *in_use.entry(scene_id.to_string()).or_default() += 1;
        }
    }

    fn release(&self, scene_id: &str) {
        if let Ok(mut in_use) = self.in_use.lock()
            && let Some(count) = in_use.get_mut(scene_id)
        {
            *count -= 1;
            if *count == 0 {
                in_use.remove(scene_id);
            }
        }
    }

    /// Removes the least recently used complete copies not in use until the rest fit the budget.
    fn evict_over_budget(&self) {
        let Ok(entries) = std::fs::read_dir(&self.root) else {
            return;
        };
        let mut copies: Vec<(std::time::SystemTime, u64, String)> = entries
            .flatten()
            .filter_map(|entry| {
                let name = entry.file_name().to_string_lossy().into_owned();
                let used = std::fs::metadata(entry.path().join(COMPLETE))
                    .and_then(|meta| meta.modified())
                    .ok()?;
                Some((used, folder_bytes(&entry.path()), name))
            })
            .collect();
        let mut total: u64 = copies.iter().map(|(_, bytes, _)| bytes).sum();
        copies.sort();
        let Ok(in_use) = self.in_use.lock() else {
            return;
        };
        for (_, bytes, scene_id) in copies {
            if total <= self.budget_bytes {
                break;
            }
            if in_use.contains_key(&scene_id) {
                continue;
            }
            if std::fs::remove_dir_all(self.root.join(&scene_id)).is_ok() {
                total = total.saturating_sub(bytes);
                tracing::info!(%scene_id, bytes, "evicted a scene copy over the cache budget");
            }
        }
    }
}

fn touch(path: &Path) {
    if let Ok(file) = std::fs::File::options().append(true).open(path) {
        let _ = file.set_modified(std::time::SystemTime::now());
    }
}

fn folder_bytes(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|entry| match entry.file_type() {
            Ok(kind) if kind.is_dir() => folder_bytes(&entry.path()),
            _ => entry.metadata().map(|meta| meta.len()).unwrap_or(0),
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::LocalBlobStore;

    fn store_scene(blobs: &LocalBlobStore, scene_id: &str, bytes: usize) {
        blobs
            .put_bytes(
                &format!("scenes/{scene_id}/files/images/a.png"),
                &vec![1; bytes],
            )
            .unwrap();
        blobs
            .put_bytes(&format!("scenes/{scene_id}/files/sparse/points.txt"), b"p")
            .unwrap();
    }

    #[test]
    fn copies_are_reused_and_the_oldest_unused_go_over_budget() {
        let dir = tempfile::tempdir().unwrap();
        let blobs = LocalBlobStore::open(&dir.path().join("blobs")).unwrap();
        for scene in ["a", "b", "c"] {
            store_scene(&blobs, scene, 1000);
        }
        let cache = Arc::new(SceneFileCache::new(dir.path().join("cache"), 2500));
        let a = cache.checkout(&blobs, "a").unwrap();
        assert_eq!(
            std::fs::read(a.dir.join("images/a.png")).unwrap().len(),
            1000
        );
        assert!(a.dir.join("sparse/points.txt").is_file());
        drop(a);
        let b = cache.checkout(&blobs, "b").unwrap();
        // Reusing `a` makes `b` the least recently used, but `b` is held.
        std::thread::sleep(std::time::Duration::from_millis(20));
        drop(cache.checkout(&blobs, "a").unwrap());
        let c = cache.checkout(&blobs, "c").unwrap();
        // Three copies pass the budget; `b` is in use, so `a` goes although used later.
        assert!(b.dir.is_dir() && c.dir.is_dir());
        assert!(!dir.path().join("cache/a").exists());
        drop((b, c));
        // A copy already here is not fetched again.
        blobs.delete_prefix("scenes/c").unwrap();
        assert!(
            cache
                .checkout(&blobs, "c")
                .unwrap()
                .dir
                .join("images/a.png")
                .is_file()
        );
        // No temporary folders are left.
        let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("cache"))
            .unwrap()
            .flatten()
            .filter(|entry| entry.file_name().to_string_lossy().contains(TEMP_MARKER))
            .collect();
        assert!(leftovers.is_empty());
    }
}
