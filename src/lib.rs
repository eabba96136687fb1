//! segsplat: open-vocabulary 3D segmentation with Segment-then-Splat Gaussian scenes.
//!
//! Dependency direction (nothing below imports upward):
//! `api`, `jobs`, `pipeline` -> `splat`, `segment`, `language`, `models`, `store` -> `gpu`, `scene`.

pub mod api;
pub mod config;
pub mod eval;
pub mod gpu;
pub mod jobs;
pub mod language;
pub mod models;
pub mod pipeline;
pub mod scene;
pub mod segment;
pub mod splat;
pub mod store;

/// Generated gRPC types and services (`proto/segsplat/v1`).
pub mod proto {
    #![allow(clippy::all, missing_docs)]
    tonic::include_proto!("segsplat.v1");

    /// Encoded file descriptors, for the gRPC reflection service.
    pub const FILE_DESCRIPTOR_SET: &[u8] =
        tonic::include_file_descriptor_set!("segsplat_descriptor");
}
