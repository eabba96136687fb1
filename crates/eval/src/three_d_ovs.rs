//! 3D-OVS ground truth: `segmentations/classes.txt` names the classes, and
//! `segmentations/<view>/<class>.png` is a binary mask per class visible in that view.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::error::EvalError;
use super::ground_truth::{
    GroundTruthFrame, GroundTruthQuery, keep_non_empty, sorted_entries, stem,
};
use segsplat_vision::segment::mask::BitMask;

const CLASSES_FILE: &str = "classes.txt";

/// The `segmentations` folder at `path` (the scene folder or the folder itself), if any.
pub(crate) fn find(path: &Path) -> Option<PathBuf> {
    [path.to_path_buf(), path.join("segmentations")]
        .into_iter()
        .find(|folder| folder.join(CLASSES_FILE).is_file())
}

/// Every view folder of a `segmentations` folder, one frame each.
pub(crate) fn load(
    segmentations: &Path,
    frame_names: &[String],
) -> Result<Vec<GroundTruthFrame>, EvalError> {
    let classes = read_classes(&segmentations.join(CLASSES_FILE))?;
    let mut index_from_stem = HashMap::new();
    for (index, name) in frame_names.iter().enumerate() {
        index_from_stem.entry(stem(name)).or_insert(index);
    }
    let mut frames = Vec::new();
    for view_folder in sorted_entries(segmentations)? {
        if !view_folder.is_dir() {
            continue;
        }
        let view = view_folder
            .file_name()
            .map(|name| name.to_string_lossy().into_owned())
            .unwrap_or_default();
        // Hidden folders (editor or notebook caches) are not views.
        if view.starts_with('.') {
            continue;
        }
        let frame_index = match_view(segmentations, &view, &index_from_stem, frame_names)?;
        let frame_name = frame_names
            .get(frame_index)
            .cloned()
            .unwrap_or_else(|| view.clone());
        let mut queries = load_view(&view_folder, &view, &classes)?;
        keep_non_empty(&frame_name, &mut queries);
        frames.push(GroundTruthFrame {
            frame_name,
            frame_index,
            queries,
        });
    }
    if frames.is_empty() {
        return Err(EvalError::NotFound {
            path: segmentations.to_path_buf(),
            looked_for: "3D-OVS view folders (segmentations/<view>/<class>.png)".to_owned(),
        });
    }
    Ok(frames)
}

fn read_classes(path: &Path) -> Result<Vec<String>, EvalError> {
    let text = std::fs::read_to_string(path).map_err(|error| EvalError::io(path, error))?;
    let classes: Vec<String> = text
        .lines()
        .map(str::trim)
        .filter(|line| !line.is_empty())
        .map(str::to_owned)
        .collect();
    if classes.is_empty() {
        return Err(EvalError::invalid(path, "lists no class"));
    }
    Ok(classes)
}

/// A view folder's frame: the scene frame with the same file stem, else the folder's name read
/// as a frame index.
fn match_view(
    segmentations: &Path,
    view: &str,
    index_from_stem: &HashMap<&str, usize>,
    frame_names: &[String],
) -> Result<usize, EvalError> {
    if let Some(&index) = index_from_stem.get(view) {
        return Ok(index);
    }
    let unmatched = |reason: String| EvalError::UnmatchedView {
        path: segmentations.to_path_buf(),
        view: view.to_owned(),
        reason,
    };
    let Ok(index) = view.parse::<usize>() else {
        return Err(unmatched(if frame_names.is_empty() {
            "no frame names were given and the view name is not a frame index".to_owned()
        } else {
            format!(
                "no frame has that file stem (the first frame is '{}') and it is not a number",
                frame_names[0]
            )
        }));
    };
    if !frame_names.is_empty() && index >= frame_names.len() {
        return Err(unmatched(format!(
            "no frame has that file stem, and as a frame index it is past the scene's {} frames",
            frame_names.len()
        )));
    }
    Ok(index)
}

/// The masks of one view, in `classes.txt` order; classes without a PNG are not in this view.
fn load_view(
    view_folder: &Path,
    view: &str,
    classes: &[String],
) -> Result<Vec<GroundTruthQuery>, EvalError> {
    warn_about_unlisted_masks(view_folder, classes)?;
    let mut queries: Vec<GroundTruthQuery> = Vec::new();
    for class in classes {
        let path = view_folder.join(format!("{class}.png"));
        if !path.is_file() {
            continue;
        }
        let mask = read_mask(&path)?;
        if let Some(first) = queries.first()
            && (first.mask.width(), first.mask.height()) != (mask.width(), mask.height())
        {
            return Err(EvalError::MaskSizeMismatch {
                path,
                view: view.to_owned(),
                found_width: mask.width(),
                found_height: mask.height(),
                expected_width: first.mask.width(),
                expected_height: first.mask.height(),
            });
        }
        queries.push(GroundTruthQuery {
            text: class.clone(),
            mask,
        });
    }
    Ok(queries)
}

/// A PNG that names no listed class is most likely a spelling mismatch with `classes.txt`,
/// which would otherwise silently drop that class from the evaluation.
fn warn_about_unlisted_masks(view_folder: &Path, classes: &[String]) -> Result<(), EvalError> {
    for path in sorted_entries(view_folder)? {
        let is_png = path.extension().is_some_and(|ext| ext == "png");
        let name = path.file_stem().map(|stem| stem.to_string_lossy());
        if let Some(name) = name.filter(|_| is_png)
            && !classes.iter().any(|class| *class == name)
        {
            tracing::warn!(mask = %path.display(), "mask names no class in classes.txt; ignored");
        }
    }
    Ok(())
}

/// Any nonzero colour channel is inside; alpha is ignored. Read at 16 bits so that a faint
/// 16-bit value is not rounded to zero.
fn read_mask(path: &Path) -> Result<BitMask, EvalError> {
    let image = image::ImageReader::open(path)
        .map_err(|error| EvalError::io(path, error))?
        .with_guessed_format()
        .map_err(|error| EvalError::io(path, error))?
        .decode()
        .map_err(|source| EvalError::Image {
            path: path.to_path_buf(),
            source,
        })?
        .into_rgb16();
    let inside: Vec<bool> = image.pixels().map(|pixel| pixel.0 != [0; 3]).collect();
    BitMask::from_bools(image.width(), image.height(), &inside)
        .map_err(|error| EvalError::invalid(path, error.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground_truth::{GroundTruthFormat, load_ground_truth};
    use image::{GrayImage, Luma, Rgb, RgbImage};

    /// A `width x height` mask PNG with the `side x side` square at the origin set.
    fn write_square(path: &Path, width: u32, height: u32, side: u32) {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).expect("view folder");
        }
        GrayImage::from_fn(width, height, |x, y| {
            Luma([if x < side && y < side { 255 } else { 0 }])
        })
        .save(path)
        .expect("write png");
    }

    fn frame_names() -> Vec<String> {
        ["00.jpg", "01.jpg", "02.jpg", "10.jpg"]
            .map(str::to_owned)
            .to_vec()
    }

    fn scene_with_classes(classes: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().expect("tempdir");
        let segmentations = dir.path().join("segmentations");
        std::fs::create_dir_all(&segmentations).expect("segmentations");
        std::fs::write(segmentations.join(CLASSES_FILE), classes).expect("classes");
        dir
    }

    #[test]
    fn views_match_by_stem_then_by_index_and_missing_classes_are_not_queries() {
        let dir = scene_with_classes("banana\n\n red apple \ncup\n");
        let segmentations = dir.path().join("segmentations");
        write_square(&segmentations.join("00/banana.png"), 8, 6, 2);
        write_square(&segmentations.join("00/red apple.png"), 8, 6, 3);
        write_square(&segmentations.join("10/banana.png"), 8, 6, 4);
        // Only the blue channel is set: still inside.
        RgbImage::from_fn(8, 6, |x, _| Rgb([0, 0, if x == 0 { 1 } else { 0 }]))
            .save(segmentations.join("10/cup.png"))
            .expect("write png");
        // "2" is no frame's stem, so it is read as frame index 2.
        write_square(&segmentations.join("2/cup.png"), 8, 6, 1);

        let (format, frames) = load_ground_truth(dir.path(), &frame_names()).expect("loads");
        assert_eq!(format, GroundTruthFormat::ThreeDOvs);
        type FrameSummary<'a> = (usize, &'a str, Vec<(&'a str, u64)>);
        let summary: Vec<FrameSummary> = frames
            .iter()
            .map(|frame| {
                let queries = frame
                    .queries
                    .iter()
                    .map(|query| (query.text.as_str(), query.mask.area()))
                    .collect();
                (frame.frame_index, frame.frame_name.as_str(), queries)
            })
            .collect();
        assert_eq!(
            summary,
            [
                (0, "00.jpg", vec![("banana", 4), ("red apple", 9)]),
                (2, "02.jpg", vec![("cup", 1)]),
                (3, "10.jpg", vec![("banana", 16), ("cup", 6)]),
            ]
        );
    }

    #[test]
    fn segmentations_folder_itself_is_accepted_and_names_fall_back_to_views() {
        let dir = scene_with_classes("banana\n");
        let segmentations = dir.path().join("segmentations");
        write_square(&segmentations.join("5/banana.png"), 4, 4, 2);
        std::fs::create_dir_all(segmentations.join(".ipynb_checkpoints")).expect("hidden");
        let (_, frames) = load_ground_truth(&segmentations, &[]).expect("loads");
        assert_eq!(frames.len(), 1);
        assert_eq!(
            (frames[0].frame_index, frames[0].frame_name.as_str()),
            (5, "5")
        );
    }

    #[test]
    fn a_view_matching_no_frame_is_an_error_naming_it() {
        let dir = scene_with_classes("banana\n");
        let segmentations = dir.path().join("segmentations");
        write_square(&segmentations.join("extra/banana.png"), 4, 4, 2);
        let error = load_ground_truth(dir.path(), &frame_names()).expect_err("unmatched");
        assert!(matches!(&error, EvalError::UnmatchedView { view, .. } if view == "extra"));

        let dir = scene_with_classes("banana\n");
        write_square(&dir.path().join("segmentations/7/banana.png"), 4, 4, 2);
        let message = load_ground_truth(dir.path(), &frame_names())
            .expect_err("index past the end")
            .to_string();
        assert!(
            message.contains("'7'") && message.contains("4 frames"),
            "{message}"
        );
    }

    #[test]
    fn masks_of_one_view_must_share_a_size() {
        let dir = scene_with_classes("banana\ncup\n");
        let segmentations = dir.path().join("segmentations");
        write_square(&segmentations.join("00/banana.png"), 8, 6, 2);
        write_square(&segmentations.join("00/cup.png"), 6, 8, 2);
        let error = load_ground_truth(dir.path(), &frame_names()).expect_err("sizes differ");
        assert!(matches!(
            error,
            EvalError::MaskSizeMismatch {
                found_width: 6,
                expected_width: 8,
                ..
            }
        ));
    }

    #[test]
    fn an_undecodable_mask_names_the_file() {
        let dir = scene_with_classes("banana\n");
        let view = dir.path().join("segmentations/00");
        std::fs::create_dir_all(&view).expect("view");
        std::fs::write(view.join("banana.png"), b"not a png").expect("write");
        let message = load_ground_truth(dir.path(), &frame_names())
            .expect_err("bad png")
            .to_string();
        assert!(message.contains("banana.png"), "{message}");
    }

    #[test]
    fn empty_class_list_is_an_error() {
        let dir = scene_with_classes("\n  \n");
        let message = load_ground_truth(dir.path(), &[])
            .expect_err("no classes")
            .to_string();
        assert!(
            message.contains("classes.txt") && message.contains("no class"),
            "{message}"
        );
    }
}
