//! A finished training job's scene as the serving side loads it: the Gaussians (`scene.ply`),
//! their object ids (`labels.npy`, PLY order) and the cameras they were trained from
//! (`cameras.json`), and for a dynamic scene its deformation field (`deformation.json` and
//! `deformation.bin`), from a job's blob prefix or from a local output folder.

use super::ServingError;
use crate::store::{BlobError, BlobStore};
use segsplat_engine::GaussianModel;
use segsplat_engine::deform::{DEFORMATION_FILE, DEFORMATION_WEIGHTS_FILE, StoredDeformation};
use segsplat_engine::labels::read_labels;
use segsplat_engine::ply::read_ply;
use segsplat_method::cameras::{CAMERAS_FILE, SceneCamera};
use segsplat_method::scene_files::{LABELS_FILE, SCENE_FILE};

/// Reads a stored `cameras.json`.
pub fn parse_cameras(bytes: &[u8]) -> Result<Vec<SceneCamera>, ServingError> {
    serde_json::from_slice(bytes).map_err(|error| ServingError::Corrupt {
        file: CAMERAS_FILE.to_string(),
        problem: error.to_string(),
    })
}

#[derive(Debug, Clone)]
pub struct TrainedScene {
    /// Gaussians with their object ids filled from the labels.
    pub model: GaussianModel,
    /// SH degree the PLY carries.
    pub sh_degree: u32,
    /// In the dataset's frame order: frame index = position.
    pub cameras: Vec<SceneCamera>,
    /// The deformation field of a dynamic scene (`model` is then its canonical Gaussians).
    pub deformation: Option<StoredDeformation>,
}

impl TrainedScene {
    /// Loads the files under a job's output prefix in the blob store (blocking I/O).
    pub fn from_blobs(blobs: &dyn BlobStore, prefix: &str) -> Result<Self, ServingError> {
        Self::from_reader(|file| {
            let key = format!("{prefix}/{file}");
            blobs.get_bytes(&key).map_err(|error| match error {
                BlobError::NotFound { .. } => ServingError::MissingFile {
                    file: file.to_string(),
                    location: prefix.to_string(),
                },
                other => ServingError::Storage(other.to_string()),
            })
        })
    }

    fn from_reader(
        read: impl Fn(&str) -> Result<Vec<u8>, ServingError>,
    ) -> Result<Self, ServingError> {
        let ply = read(SCENE_FILE)?;
        let imported = read_ply(ply.as_slice()).map_err(|error| ServingError::Corrupt {
            file: SCENE_FILE.to_string(),
            problem: error.to_string(),
        })?;
        let mut model = imported.model;
        let labels = read(LABELS_FILE)?;
        model.object_ids =
            read_labels(labels.as_slice(), model.len()).map_err(|error| ServingError::Corrupt {
                file: LABELS_FILE.to_string(),
                problem: error.to_string(),
            })?;
        let cameras = parse_cameras(&read(CAMERAS_FILE)?)?;
        let deformation = match read(DEFORMATION_FILE) {
            Ok(header) => {
                let weights = read(DEFORMATION_WEIGHTS_FILE)?;
                Some(
                    StoredDeformation::parse(&header, &weights).map_err(|error| {
                        ServingError::Corrupt {
                            file: DEFORMATION_FILE.to_string(),
                            problem: error.to_string(),
                        }
                    })?,
                )
            }
            Err(ServingError::MissingFile { .. }) => None,
            Err(error) => return Err(error),
        };
        Ok(Self {
            model,
            sh_degree: imported.sh_degree,
            cameras,
            deformation,
        })
    }
}
