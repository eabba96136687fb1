//! Which of an upload's files the dataset uses: what loading it again reads (the format's own
//! files, every frame image, every mask). The rest (stray exports, thumbnails, thousands of
//! unrelated files) is not stored; the upload reports how much was left out.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use super::dataset_path::contained_relative_path;
use super::{Scene, SceneFormat, blender, colmap, nerfies, nerfstudio, neu3d};

/// Paths relative to `scene.root` of every file the dataset needs.
pub fn used_files(scene: &Scene) -> BTreeSet<PathBuf> {
    let root = &scene.root;
    let mut used: BTreeSet<PathBuf> = scene
        .frames
        .iter()
        .map(|frame| frame.image_path.clone())
        .collect();
    if let Some(masks) = &scene.masks {
        used.extend(masks.paths.iter().flatten().flatten().cloned());
    }
    let mut keep_if_present = |relative: PathBuf| {
        if root.join(&relative).is_file() {
            used.insert(relative);
        }
    };
    match scene.format {
        SceneFormat::Colmap => {
            if let Some(location) = colmap::find_model(root) {
                for file in files_in(&root.join(&location.relative_dir)) {
                    keep_if_present(location.relative_dir.join(file));
                }
            }
        }
        SceneFormat::Nerfstudio => {
            keep_if_present(PathBuf::from(nerfstudio::TRANSFORMS_FILE));
            if let Some(ply) = nerfstudio_point_file(root) {
                keep_if_present(ply);
            }
        }
        SceneFormat::Blender => {
            for file in [
                blender::TRAIN_TRANSFORMS_FILE,
                blender::VAL_TRANSFORMS_FILE,
                blender::TEST_TRANSFORMS_FILE,
            ] {
                keep_if_present(PathBuf::from(file));
            }
        }
        SceneFormat::Nerfies => {
            for file in nerfies::METADATA_FILES {
                keep_if_present(PathBuf::from(file));
            }
            let cameras = PathBuf::from(nerfies::CAMERA_DIR);
            for file in files_in(&root.join(&cameras)) {
                keep_if_present(cameras.join(file));
            }
        }
        SceneFormat::Neu3d => keep_if_present(PathBuf::from(neu3d::POSES_BOUNDS_FILE)),
    }
    // Compared with paths found by walking the folder, which never hold `.` components.
    used.into_iter()
        .map(|path| {
            path.components()
                .filter(|component| !matches!(component, std::path::Component::CurDir))
                .collect()
        })
        .collect()
}

/// Names of the plain files directly in `dir`.
fn files_in(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter(|entry| entry.file_type().is_ok_and(|kind| kind.is_file()))
        .map(|entry| PathBuf::from(entry.file_name()))
        .collect()
}

/// `ply_file_path` of `transforms.json`, when it names a file inside the dataset.
fn nerfstudio_point_file(root: &Path) -> Option<PathBuf> {
    let bytes = std::fs::read(root.join(nerfstudio::TRANSFORMS_FILE)).ok()?;
    let json: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    contained_relative_path(json.get("ply_file_path")?.as_str()?)
}
