//! The service edge: REST (axum) and gRPC (tonic) APIs, authentication, metrics, health, and
//! the process lifecycle that ties them to the store and the worker pool.

mod auth;
pub mod error;
mod exports;
mod grpc;
mod ingest;
mod job_bounds;
mod jobs;
mod masks;
mod metrics;
mod objects;
mod openapi;
mod ops;
pub mod query;
mod router;
mod scenes;
mod server;
pub mod serving;
mod state;
mod upload_commit;

pub use openapi::ApiDoc;
pub use server::{RunningService, ServiceBuilder, ServiceError, ServiceMode};
