//! What the training tests share: the synthetic scene and a short schedule. Each test makes a
//! GPU context of its own (`gpu_support::new_gpu_context`): the steady-step test counts what its
//! context creates.

use segsplat_engine::train::TrainConfig;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{SYNTHETIC_BACKGROUND, SyntheticSpec, write_colmap};
use segsplat_scene::{LoadOptions, Scene, load_scene};

pub(crate) fn synthetic_scene(dir: &std::path::Path) -> Scene {
    let spec = SyntheticSpec {
        frame_count: 32,
        width: 64,
        height: 48,
        ..Default::default()
    };
    write_colmap(dir, &spec, ColmapEncoding::Text).unwrap();
    load_scene(dir, &LoadOptions::default()).unwrap()
}

pub(crate) fn config(steps: u32) -> TrainConfig {
    TrainConfig {
        steps,
        max_resolution: None,
        background: SYNTHETIC_BACKGROUND.map(|c| c as f32 / 255.0),
        sh_degree_interval: Some(100),
        densify_from: Some(100),
        densify_until: Some(400),
        densify_interval: Some(100),
        opacity_reset_interval: Some(0),
        ..Default::default()
    }
}
