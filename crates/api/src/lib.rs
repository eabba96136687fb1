//! The service edge: REST (axum) and gRPC (tonic) APIs, authentication, metrics, health, and
//! the process lifecycle that ties them to the store and the worker pool.

mod auth;
mod console;
pub mod error;
mod exports;
mod extract;
mod gpu_release;
mod grpc;
mod grpc_calls;
mod grpc_convert;
mod grpc_reflection;
mod jobs;
mod json_numbers;
mod masks;
pub mod metrics;
mod objects;
mod openapi;
mod openapi_shared;
mod ops;
mod params;
pub mod query;
mod readiness;
mod router;
mod scenes;
mod schema_names;
mod server;
mod state;
mod view_schema;
mod workers;

pub use openapi::ApiDoc;
pub use server::{RunningService, ServiceBuilder, ServiceError, ServiceMode};

/// Generated gRPC types and services (`crates/api/proto/segsplat/v1`).
pub mod proto {
    #![allow(clippy::all, missing_docs)]
    tonic::include_proto!("segsplat.v1");

    /// Encoded file descriptors, for the gRPC reflection service.
    pub const FILE_DESCRIPTOR_SET: &[u8] =
        tonic::include_file_descriptor_set!("segsplat_descriptor");
}
