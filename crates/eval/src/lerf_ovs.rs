//! LERF_OVS ground truth as LangSplat released it: `label/<scene>/frame_00041.json` (plus the
//! `.jpg` it was drawn on), each holding polygons with a category name.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::error::EvalError;
use super::ground_truth::{
    GroundTruthFrame, GroundTruthQuery, MAX_SIDE, keep_non_empty, sorted_entries, stem,
};
use super::polygon::rasterize_polygon;

/// The parts of a label file we use; the release's other fields (`bbox`, ids) are ignored.
#[derive(Deserialize)]
struct LabelFile {
    info: LabelInfo,
    objects: Vec<LabelObject>,
}

#[derive(Deserialize)]
struct LabelInfo {
    name: String,
    width: u32,
    height: u32,
}

#[derive(Deserialize)]
struct LabelObject {
    category: String,
    /// One polygon of `[x, y]` pixel coordinates.
    segmentation: Vec<[f64; 2]>,
}

/// The label folder at or directly under `path`, `None` when there is none.
pub(crate) fn find(path: &Path) -> Result<Option<PathBuf>, EvalError> {
    if !label_files(path)?.is_empty() {
        return Ok(Some(path.to_path_buf()));
    }
    let mut found = Vec::new();
    for entry in sorted_entries(path)? {
        if entry.is_dir() && !label_files(&entry)?.is_empty() {
            found.push(entry);
        }
    }
    match found.len() {
        0 => Ok(None),
        1 => Ok(found.pop()),
        _ => {
            let names: Vec<String> = found
                .iter()
                .filter_map(|folder| folder.file_name())
                .map(|name| name.to_string_lossy().into_owned())
                .collect();
            Err(EvalError::invalid(
                path,
                format!(
                    "holds LERF_OVS labels for several scenes ({}); pass one scene's label folder",
                    names.join(", ")
                ),
            ))
        }
    }
}

/// Label files in `folder` with their frame numbers: `*.json` whose name ends in a number
/// (`frame_00041.json` -> 41). Other files are not labels and are skipped.
fn label_files(folder: &Path) -> Result<Vec<(PathBuf, String)>, EvalError> {
    let mut files = Vec::new();
    for path in sorted_entries(folder)? {
        let is_json = path.extension().is_some_and(|ext| ext == "json");
        let Some(file_stem) = path.file_stem().and_then(|stem| stem.to_str()) else {
            continue;
        };
        let number = &file_stem[file_stem.len() - trailing_digits(file_stem)..];
        if is_json && !number.is_empty() && path.is_file() {
            files.push((path.clone(), number.to_owned()));
        }
    }
    Ok(files)
}

fn trailing_digits(text: &str) -> usize {
    text.bytes().rev().take_while(u8::is_ascii_digit).count()
}

/// Every label file of one scene's label folder, one frame each.
pub(crate) fn load(
    folder: &Path,
    frame_names: &[String],
) -> Result<Vec<GroundTruthFrame>, EvalError> {
    label_files(folder)?
        .into_iter()
        .map(|(path, number)| load_file(&path, &number, frame_names))
        .collect()
}

fn load_file(
    path: &Path,
    number: &str,
    frame_names: &[String],
) -> Result<GroundTruthFrame, EvalError> {
    let frame_index = frame_index(path, number, frame_names)?;
    let text = std::fs::read_to_string(path).map_err(|error| EvalError::io(path, error))?;
    let label: LabelFile = serde_json::from_str(&text).map_err(|source| EvalError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    let LabelInfo {
        name,
        width,
        height,
    } = label.info;
    if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
        return Err(EvalError::invalid(
            path,
            format!("image size {width}x{height} is not between 1 and {MAX_SIDE} pixels a side"),
        ));
    }
    if let Some(scene_name) = frame_names.get(frame_index)
        && stem(scene_name) != stem(&name)
    {
        tracing::warn!(
            label = %path.display(),
            label_frame = %name,
            scene_frame = %scene_name,
            frame_index,
            "LERF_OVS label is indexed by its file number, but the scene's frame at that index has another name"
        );
    }
    let mut queries: Vec<GroundTruthQuery> = Vec::new();
    for object in label.objects {
        if object.segmentation.len() < 3 {
            tracing::warn!(
                label = %path.display(),
                category = %object.category,
                points = object.segmentation.len(),
                "polygon with fewer than 3 points skipped"
            );
            continue;
        }
        let polygon = rasterize_polygon(&object.segmentation, width, height);
        // Several objects of one category are one query, their masks united, as LangSplat's
        // evaluation stacks them.
        match queries
            .iter_mut()
            .find(|query| query.text == object.category)
        {
            Some(query) => query
                .mask
                .union_with(&polygon)
                .map_err(|error| EvalError::invalid(path, error.to_string()))?,
            None => queries.push(GroundTruthQuery {
                text: object.category,
                mask: polygon,
            }),
        }
    }
    keep_non_empty(&name, &mut queries);
    Ok(GroundTruthFrame {
        frame_name: name,
        frame_index,
        queries,
    })
}

/// LangSplat's convention: the file number counts frames from 1.
fn frame_index(path: &Path, number: &str, frame_names: &[String]) -> Result<usize, EvalError> {
    let number: usize = number
        .parse()
        .map_err(|_| EvalError::invalid(path, format!("frame number {number} is too large")))?;
    let Some(frame_index) = number.checked_sub(1) else {
        return Err(EvalError::invalid(
            path,
            "frame number 0: LERF_OVS label files count frames from 1",
        ));
    };
    if !frame_names.is_empty() && frame_index >= frame_names.len() {
        return Err(EvalError::invalid(
            path,
            format!(
                "frame number {number} (index {frame_index}) is past the scene's {} frames",
                frame_names.len()
            ),
        ));
    }
    Ok(frame_index)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground_truth::{GroundTruthFormat, load_ground_truth};
    use serde_json::json;

    fn square(x: f64, y: f64, side: f64) -> serde_json::Value {
        json!([[x, y], [x + side, y], [x + side, y + side], [x, y + side]])
    }

    fn write_label(folder: &Path, number: u32, objects: serde_json::Value) {
        std::fs::create_dir_all(folder).expect("label folder");
        let label = json!({
            "info": {"name": format!("frame_{number:05}.jpg"), "width": 40, "height": 30},
            "objects": objects,
        });
        let path = folder.join(format!("frame_{number:05}.json"));
        std::fs::write(path, label.to_string()).expect("write label");
    }

    fn names(count: usize) -> Vec<String> {
        (1..=count).map(|n| format!("frame_{n:05}.jpg")).collect()
    }

    #[test]
    fn same_category_objects_are_one_query_and_extra_fields_are_ignored() {
        let dir = tempfile::tempdir().expect("tempdir");
        let folder = dir.path().join("label").join("figurines");
        write_label(
            &folder,
            41,
            json!([
                {"category": "old camera", "segmentation": square(0.0, 0.0, 4.0), "bbox": [0, 0, 4, 4], "id": 1},
                {"category": "mug", "segmentation": [[10.0, 10.0], [20.0, 10.0], [10.0, 20.0]]},
                {"category": "old camera", "segmentation": square(20.0, 0.0, 2.0)},
                {"category": "line", "segmentation": [[1.0, 1.0], [5.0, 5.0]]},
            ]),
        );
        let (format, frames) = load_ground_truth(&folder, &names(50)).expect("loads");
        assert_eq!(format, GroundTruthFormat::LerfOvs);
        assert_eq!(frames.len(), 1);
        let frame = &frames[0];
        assert_eq!(
            (frame.frame_name.as_str(), frame.frame_index),
            ("frame_00041.jpg", 40)
        );
        let texts: Vec<&str> = frame.queries.iter().map(|q| q.text.as_str()).collect();
        assert_eq!(texts, ["old camera", "mug"]);
        let camera = &frame.queries[0].mask;
        assert_eq!((camera.width(), camera.height()), (40, 30));
        assert_eq!(camera.area(), 25 + 9);
        assert!(camera.get(0, 0) && camera.get(22, 2) && !camera.get(10, 0));
        assert_eq!(frame.queries[1].mask.area(), 66);
    }

    #[test]
    fn parent_folder_is_accepted_and_frames_sort_by_number() {
        let dir = tempfile::tempdir().expect("tempdir");
        let folder = dir.path().join("ramen");
        write_label(
            &folder,
            100,
            json!([{"category": "bowl", "segmentation": square(1.0, 1.0, 3.0)}]),
        );
        write_label(
            &folder,
            7,
            json!([{"category": "egg", "segmentation": square(1.0, 1.0, 3.0)}]),
        );
        std::fs::write(folder.join("notes.json"), "not a label").expect("write");
        let (_, frames) = load_ground_truth(dir.path(), &[]).expect("loads");
        let indices: Vec<usize> = frames.iter().map(|f| f.frame_index).collect();
        assert_eq!(indices, [6, 99]);
    }

    #[test]
    fn several_scenes_under_one_parent_are_ambiguous() {
        let dir = tempfile::tempdir().expect("tempdir");
        for scene in ["ramen", "teatime"] {
            write_label(&dir.path().join(scene), 1, json!([]));
        }
        let message = load_ground_truth(dir.path(), &[])
            .expect_err("ambiguous")
            .to_string();
        assert!(message.contains("ramen, teatime"), "{message}");
    }

    #[test]
    fn broken_json_names_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(
            dir.path().join("frame_00003.json"),
            "{\"info\": {\"name\": 3}}",
        )
        .expect("write");
        let error = load_ground_truth(dir.path(), &[]).expect_err("bad json");
        assert!(matches!(error, EvalError::Json { .. }));
        let message = error.to_string();
        assert!(
            message.contains("frame_00003.json") && message.contains("invalid type"),
            "{message}"
        );
    }

    #[test]
    fn frame_numbers_must_fit_the_scene() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_label(
            dir.path(),
            41,
            json!([{"category": "cup", "segmentation": square(1.0, 1.0, 3.0)}]),
        );
        let message = load_ground_truth(dir.path(), &names(40))
            .expect_err("past the end")
            .to_string();
        assert!(message.contains("past the scene's 40 frames"), "{message}");
        assert!(load_ground_truth(dir.path(), &names(41)).is_ok());

        let zero = tempfile::tempdir().expect("tempdir");
        write_label(zero.path(), 0, json!([]));
        let message = load_ground_truth(zero.path(), &[])
            .expect_err("frame 0")
            .to_string();
        assert!(message.contains("count frames from 1"), "{message}");
    }

    #[test]
    fn absurd_image_sizes_are_rejected() {
        let dir = tempfile::tempdir().expect("tempdir");
        let label =
            json!({"info": {"name": "frame_00001.jpg", "width": 0, "height": 30}, "objects": []});
        std::fs::write(dir.path().join("frame_00001.json"), label.to_string()).expect("write");
        let message = load_ground_truth(dir.path(), &[])
            .expect_err("zero width")
            .to_string();
        assert!(message.contains("0x30"), "{message}");
    }
}
