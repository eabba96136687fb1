//! The Gaussians a training run starts from (a scene's sparse points, or random Gaussians sized
//! for the scene and the adapter), and the settings a config leaves to the adapter.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::TrainError;
use crate::background_shell::{append_points, background_shell_points};
use crate::init::gaussians_from_points;
use crate::model::GaussianModel;
use crate::train::budget::scene_random_init_count;
use crate::train::config::TrainConfig;
use crate::train::random_init::{has_sparse_points, random_visible_gaussians};
use crate::train::views::training_pixels;
use segsplat_gpu::GpuContext;
use segsplat_scene::Scene;

/// The initial model for a scene: its sparse points, or random points in the cameras' bounds.
pub fn initial_model(scene: &Scene, config: &TrainConfig) -> Result<GaussianModel, TrainError> {
    let model = match &scene.points {
        Some(points) if has_sparse_points(scene) => {
            gaussians_from_points(&points.positions, &points.colors)
        }
        _ => {
            let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0x1417);
            let count = config
                .random_init_count
                .unwrap_or_else(|| scene_sized_random_init(scene, config, false));
            random_visible_gaussians(scene, count, &mut rng)
        }
    };
    if model.is_empty() {
        return Err(TrainError::EmptyModel);
    }
    Ok(model)
}

/// The random start [`scene_random_init_count`] sizes for `scene` under `config` (its training
/// views at its resolution), on a software adapter or not.
pub fn scene_sized_random_init(scene: &Scene, config: &TrainConfig, software: bool) -> usize {
    let pixels = training_pixels(scene, config.max_resolution, config.eval_split_every);
    scene_random_init_count(pixels, software)
}

/// Fills in `random_init_count` when `config` leaves it out and `scene` has no sparse points
/// (so the start is random), sized for the adapter of `ctx`; an explicit count is kept. The
/// config then says what the job started from.
pub fn resolve_random_init(config: &mut TrainConfig, scene: &Scene, ctx: &GpuContext) {
    if config.random_init_count.is_none() && !has_sparse_points(scene) {
        config.random_init_count = Some(scene_sized_random_init(
            scene,
            config,
            ctx.report.is_software,
        ));
    }
}

/// Fills in what `config` leaves to the adapter of `ctx`: the random start's size
/// ([`resolve_random_init`]) and the deformation field's shape (`DeformationConfig::field_for`:
/// narrower on a CPU adapter). The trainer does this when it starts; a job does it first too,
/// so the settings it records before training say what will train.
pub fn resolve_adapter_sized(config: &mut TrainConfig, scene: &Scene, ctx: &GpuContext) {
    resolve_random_init(config, scene, ctx);
    resolve_field_shape(config, ctx);
}

pub(super) fn resolve_field_shape(config: &mut TrainConfig, ctx: &GpuContext) {
    if let Some(deformation) = config.deformation.as_mut() {
        deformation.field = Some(deformation.field_for(ctx.report.is_software));
    }
}

/// The initial model of plain training: [`initial_model`], plus `background_shell` Gaussians on
/// a far sphere when it comes from sparse points (which miss the far background: on the
/// figurine at 500 steps the shell raised held-out PSNR from 16.4 to 19.1 dB, docs/benchmarks.md).
pub fn plain_initial_model(
    scene: &Scene,
    config: &TrainConfig,
) -> Result<GaussianModel, TrainError> {
    let mut model = initial_model(scene, config)?;
    let from_points = has_sparse_points(scene);
    if from_points && config.background_shell > 0 {
        let shell = background_shell_points(scene, config.background_shell);
        append_points(&mut model, &shell);
    }
    Ok(model)
}
