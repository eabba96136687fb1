//! Evaluation: image quality of held-out views (segmentation metrics arrive with the pipeline).

pub mod image_metrics;
