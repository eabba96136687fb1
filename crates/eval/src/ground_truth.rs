//! Ground truth of the open-vocabulary segmentation benchmarks, in one shape whatever the
//! release's format: per frame, the text queries and the mask each should select.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::EvalError;
use super::{lerf_ovs, three_d_ovs};
use segsplat_vision::segment::mask::BitMask;

/// Which benchmark release a ground-truth folder is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GroundTruthFormat {
    /// LangSplat's LERF_OVS labels: `frame_00041.json` polygons per frame.
    LerfOvs,
    /// 3D-OVS: `segmentations/classes.txt` and `segmentations/<view>/<class>.png`.
    ThreeDOvs,
}

/// The labelled queries of one frame.
#[derive(Debug, Clone)]
pub struct GroundTruthFrame {
    /// The frame's name as the labels give it (LERF_OVS `info.name`), or the scene frame a
    /// 3D-OVS view folder was matched to.
    pub frame_name: String,
    /// Index into the scene's frames.
    pub frame_index: usize,
    /// One per distinct query text, each with a non-empty mask.
    pub queries: Vec<GroundTruthQuery>,
}

/// A text query and the pixels it should select, at the labels' (full photo) resolution.
#[derive(Debug, Clone)]
pub struct GroundTruthQuery {
    pub text: String,
    pub mask: BitMask,
}

/// Largest image side we accept from a label file: no benchmark photo comes near it, and a
/// corrupt size must not allocate gigabytes.
pub(crate) const MAX_SIDE: u32 = 32_768;

/// Loads the ground truth under `path`, detecting its format, for a scene whose frames are named
/// `frame_names` (in scene order; empty when unknown, which skips the checks against it).
///
/// `path` may be a 3D-OVS scene folder or its `segmentations/` folder, a LERF_OVS label folder
/// (`label/<scene>/`) or a folder holding exactly one such label folder. Frames come back sorted
/// by frame index; frames without any usable query are left out with a warning.
pub fn load_ground_truth(
    path: &Path,
    frame_names: &[String],
) -> Result<(GroundTruthFormat, Vec<GroundTruthFrame>), EvalError> {
    if !path.is_dir() {
        return Err(EvalError::NotFound {
            path: path.to_path_buf(),
            looked_for: "a folder (the path does not exist or is not a directory)".to_owned(),
        });
    }
    let (format, mut frames) = if let Some(segmentations) = three_d_ovs::find(path) {
        let frames = three_d_ovs::load(&segmentations, frame_names)?;
        (GroundTruthFormat::ThreeDOvs, frames)
    } else if let Some(label_folder) = lerf_ovs::find(path)? {
        let frames = lerf_ovs::load(&label_folder, frame_names)?;
        (GroundTruthFormat::LerfOvs, frames)
    } else {
        return Err(EvalError::NotFound {
            path: path.to_path_buf(),
            looked_for: "3D-OVS 'segmentations/classes.txt' (in the folder or as the folder), or \
                         LERF_OVS label files 'frame_<number>.json' in the folder or in one of \
                         its subfolders"
                .to_owned(),
        });
    };
    frames.retain(|frame| {
        if frame.queries.is_empty() {
            tracing::warn!(frame = %frame.frame_name, "ground-truth frame has no usable query; left out");
        }
        !frame.queries.is_empty()
    });
    frames.sort_by_key(|frame| frame.frame_index);
    for pair in frames.windows(2) {
        if pair[0].frame_index == pair[1].frame_index {
            return Err(EvalError::DuplicateFrame {
                path: path.to_path_buf(),
                frame_index: pair[0].frame_index,
                first: pair[0].frame_name.clone(),
                second: pair[1].frame_name.clone(),
            });
        }
    }
    Ok((format, frames))
}

/// Drops queries whose mask is empty: their IoU is undefined, and an object outside the view is
/// not something the benchmark asks for.
pub(crate) fn keep_non_empty(frame_name: &str, queries: &mut Vec<GroundTruthQuery>) {
    queries.retain(|query| {
        if query.mask.is_empty() {
            tracing::warn!(frame = frame_name, query = %query.text, "ground-truth mask is empty; query left out");
        }
        !query.mask.is_empty()
    });
}

/// The entries of a folder, sorted by name so that loading is deterministic.
pub(crate) fn sorted_entries(folder: &Path) -> Result<Vec<PathBuf>, EvalError> {
    let entries = std::fs::read_dir(folder).map_err(|error| EvalError::io(folder, error))?;
    let mut paths = Vec::new();
    for entry in entries {
        paths.push(entry.map_err(|error| EvalError::io(folder, error))?.path());
    }
    paths.sort();
    Ok(paths)
}

/// The file stem of a frame name (`images/00.jpg` -> `00`), how label names are matched.
pub(crate) fn stem(name: &str) -> &str {
    Path::new(name)
        .file_stem()
        .and_then(|stem| stem.to_str())
        .unwrap_or(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_folder_says_what_was_looked_for() {
        let dir = tempfile::tempdir().expect("tempdir");
        let error = load_ground_truth(dir.path(), &[]).expect_err("nothing there");
        let message = error.to_string();
        assert!(message.contains("classes.txt") && message.contains("frame_<number>.json"));
        let missing = dir.path().join("missing");
        assert!(matches!(
            load_ground_truth(&missing, &[]),
            Err(EvalError::NotFound { .. })
        ));
    }

    #[test]
    fn stems_ignore_folders_and_extensions() {
        assert_eq!(stem("images/00.jpg"), "00");
        assert_eq!(stem("frame_00041.jpg"), "frame_00041");
        assert_eq!(stem("plain"), "plain");
    }
}
