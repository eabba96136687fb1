//! Shared by the Segment-then-Splat end-to-end tests: the synthetic three-sphere scene at the
//! tests' size, the short training config, true full silhouettes and the mIoU arithmetic.
#![allow(dead_code)]

use glam::Vec3;
use segsplat_engine::train::{ObjectLossConfig, TrainConfig};
use segsplat_gpu::GpuContext;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{
    SYNTHETIC_BACKGROUND, SyntheticSpec, synthetic_objects, write_colmap,
};
use segsplat_scene::{Level, LoadOptions, Scene, load_scene};

// The IoU of two boolean masks, written once for every test binary that scores masks.
#[path = "../models_support/mod.rs"]
mod models_support;
#[allow(unused_imports)] // not every binary that includes this module scores masks
pub use models_support::mask_iou as iou;

/// The adapter, or `None` (skip, with the reason printed) when there is none and
/// `SEGSPLAT_SKIP_GPU_TESTS=1` is set; without that variable a missing adapter fails.
/// (A test using this module declares `mod gpu_support;` beside it.)
pub fn gpu() -> Option<GpuContext> {
    crate::gpu_support::new_gpu_context()
}

/// Writes the synthetic COLMAP scene (32 ring views at 96x72, masks at every level, points with
/// tracks) into `dir`, lets `edit` change its files, and loads it.
pub fn synthetic_scene(dir: &std::path::Path, edit: impl FnOnce(&std::path::Path)) -> Scene {
    let spec = SyntheticSpec {
        frame_count: 32,
        width: 96,
        height: 72,
        with_masks: Some(Level::ALL.to_vec()),
        ..Default::default()
    };
    write_colmap(dir, &spec, ColmapEncoding::Binary).unwrap();
    edit(dir);
    load_scene(dir, &LoadOptions::default()).unwrap()
}

/// 600 steps with densification and the object loss (m = 2): about a minute on lavapipe.
pub fn config() -> TrainConfig {
    TrainConfig {
        steps: 600,
        max_resolution: None,
        background: SYNTHETIC_BACKGROUND.map(|c| c as f32 / 255.0),
        sh_degree_interval: Some(100),
        densify_from: Some(100),
        densify_until: Some(450),
        densify_interval: Some(100),
        opacity_reset_interval: Some(0),
        object_loss: Some(ObjectLossConfig {
            objects_per_level: 2,
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// The true full silhouette of an object: every pixel whose ray meets one of its spheres.
pub fn full_truth(scene: &Scene, frame_index: usize, level: Level, object: u32) -> Vec<bool> {
    let frame = &scene.frames[frame_index];
    let k = &frame.intrinsics;
    let origin = frame.world_from_camera.transform_point3(Vec3::ZERO);
    let spheres: Vec<_> = synthetic_objects()
        .into_iter()
        .filter(|s| s.ids[level.index()] == object)
        .collect();
    (0..k.height * k.width)
        .map(|pixel| {
            let (x, y) = (pixel % k.width, pixel / k.width);
            let camera_direction = Vec3::new(
                ((f64::from(x) + 0.5 - k.cx) / k.fx) as f32,
                ((f64::from(y) + 0.5 - k.cy) / k.fy) as f32,
                1.0,
            );
            let direction = frame
                .world_from_camera
                .transform_vector3(camera_direction)
                .normalize();
            spheres.iter().any(|s| {
                let to_origin = origin - s.center;
                let b = to_origin.dot(direction);
                b * b - (to_origin.length_squared() - s.radius * s.radius) >= 0.0
            })
        })
        .collect()
}

pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}
