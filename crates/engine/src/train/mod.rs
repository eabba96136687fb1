//! Training: configuration, resident views, densification statistics and the loop.

pub mod budget;
pub mod config;
pub mod convergence;
pub mod densify_stats;
pub mod mask_iou;
pub mod object_loss;
pub mod partial_filter_report;
pub mod random_init;
pub mod schedule;
pub mod trainer;
pub mod views;

pub use config::TrainConfig;
pub use object_loss::{ObjectLossConfig, ObjectTargets, SkippedPair, ViewIdMaps};
pub use partial_filter_report::PartialFilterReport;
pub use schedule::TrainSchedule;
pub use trainer::{
    ConvergedAt, EvalReport, PartialFilterCost, PendingCheckpoint, StopCheck, TrainError,
    TrainProgress, Trainer, TrainerMeta,
};
