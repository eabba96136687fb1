//! Training: configuration, resident views, densification statistics and the loop.

pub mod config;
pub mod densify_stats;
pub mod trainer;
pub mod views;

pub use config::TrainConfig;
pub use trainer::{EvalReport, TrainError, TrainProgress, Trainer, TrainerMeta};
