//! Pieces shared by the `transforms*.json` formats (nerfstudio, Blender NeRF).

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec4};
use serde::de::DeserializeOwned;

use super::SceneError;
use super::dataset_path::contained_relative_path;

/// Reads and parses a JSON file named `file_name` under `root`.
pub fn read_json<T: DeserializeOwned>(root: &Path, file_name: &str) -> Result<T, SceneError> {
    let bytes = fs::read(root.join(file_name)).map_err(|source| match source.kind() {
        io::ErrorKind::NotFound => SceneError::Parse {
            file: file_name.to_string(),
            message: "missing".to_string(),
        },
        _ => SceneError::Io {
            file: file_name.to_string(),
            source,
        },
    })?;
    serde_json::from_slice(&bytes).map_err(|error| SceneError::Parse {
        file: file_name.to_string(),
        message: error.to_string(),
    })
}

/// A camera-to-world matrix stored as rows (3x4 or 4x4) in the OpenGL convention (x right,
/// y up, camera looking down -z), converted to OpenCV (x right, y down, z forward) by negating
/// the camera's y and z axes.
pub fn opencv_world_from_camera(
    rows: &[Vec<f64>],
    file: &str,
    frame_index: usize,
) -> Result<Mat4, SceneError> {
    let shape_ok = (rows.len() == 3 || rows.len() == 4) && rows.iter().all(|row| row.len() == 4);
    if !shape_ok {
        return Err(SceneError::Parse {
            file: file.to_string(),
            message: format!("frame {frame_index}: transform_matrix must be 3x4 or 4x4"),
        });
    }
    if rows.iter().flatten().any(|value| !value.is_finite()) {
        return Err(SceneError::Parse {
            file: file.to_string(),
            message: format!("frame {frame_index}: transform_matrix holds a non-finite value"),
        });
    }
    let row = |index: usize| -> Vec4 {
        match rows.get(index) {
            Some(row) => Vec4::new(row[0] as f32, row[1] as f32, row[2] as f32, row[3] as f32),
            None => Vec4::W,
        }
    };
    let opengl_world_from_camera = Mat4::from_cols(row(0), row(1), row(2), row(3)).transpose();
    Ok(opengl_world_from_camera * opencv_from_opengl_camera())
}

/// Flips camera y and z; its own inverse, so it also converts OpenCV poses back to OpenGL.
pub fn opencv_from_opengl_camera() -> Mat4 {
    Mat4::from_diagonal(Vec4::new(1.0, -1.0, -1.0, 1.0))
}

/// Joins a `file_path` from a transforms file onto the dataset root, refusing paths that are
/// absolute or climb out of it (the dataset came from an untrusted archive).
pub fn relative_file_path(
    file_path: &str,
    file: &str,
    frame_index: usize,
) -> Result<PathBuf, SceneError> {
    contained_relative_path(file_path).ok_or_else(|| SceneError::Parse {
        file: file.to_string(),
        message: format!(
            "frame {frame_index}: file_path {file_path:?} must be a non-empty path inside the dataset"
        ),
    })
}
