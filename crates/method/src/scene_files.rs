//! The files a trained scene is stored as: `scene.ply` (Inria layout), `labels.npy` (object ids
//! in PLY order) and `cameras.json`, written by both training methods and read by serving.

use serde::{Deserialize, Serialize};

use segsplat_engine::labels::write_labels;
use segsplat_engine::model::GaussianModel;
use segsplat_engine::ply::write_ply;
use segsplat_engine::train::EvalReport;
use segsplat_scene::Scene;

use crate::cameras::{CAMERAS_FILE, scene_cameras};

pub const SCENE_FILE: &str = "scene.ply";
pub const LABELS_FILE: &str = "labels.npy";

/// What a finished reconstruction reports.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReconstructMetrics {
    pub steps: u32,
    pub gaussians: usize,
    /// Wall time of this attempt's training (resumed attempts count only their own part).
    pub train_seconds: f64,
    pub held_out: EvalReport,
}

/// Writes `scene.ply`, `labels.npy` (object ids in PLY order) and `cameras.json` (the scene's
/// frames, so masks can be rendered per frame without the dataset) into `dir`.
pub fn write_scene_files(
    model: &GaussianModel,
    scene: &Scene,
    dir: &std::path::Path,
) -> std::io::Result<()> {
    let to_io = |error: &dyn std::fmt::Display| std::io::Error::other(error.to_string());
    let ply = std::fs::File::create(dir.join(SCENE_FILE))?;
    write_ply(model, ply).map_err(|e| to_io(&e))?;
    let labels = std::fs::File::create(dir.join(LABELS_FILE))?;
    write_labels(&model.object_ids, labels).map_err(|e| to_io(&e))?;
    let cameras = serde_json::to_vec_pretty(&scene_cameras(scene)).map_err(|e| to_io(&e))?;
    std::fs::write(dir.join(CAMERAS_FILE), cameras)?;
    Ok(())
}
