//! What can stop a trainer, from its config to the GPU.

use crate::adam::AdamError;
use crate::checkpoint::CheckpointError;
use crate::loss::LossError;
use crate::model::ModelError;
use crate::render::RenderError;
use crate::train::config::ConfigError;
use crate::train::views::ViewsError;
use segsplat_gpu::GpuError;

use super::object_step;

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Views(#[from] ViewsError),
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Loss(#[from] LossError),
    #[error(transparent)]
    Adam(#[from] AdamError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error(transparent)]
    Deform(#[from] crate::deform::DeformError),
    #[error(transparent)]
    ObjectTargets(#[from] object_step::ObjectTargetsError),
    #[error("checkpoint does not match this scene or config: {0}")]
    CheckpointMismatch(String),
    #[error("the initial model is empty: the scene has no points and random_init_count is 0")]
    EmptyModel,
    /// The stop check ([`Trainer::set_stop_check`](super::Trainer::set_stop_check)) said yes inside a long pass of one step.
    #[error("training stopped on request inside step {step}")]
    Stopped { step: u32 },
}
