//! The service edge: REST (axum) and gRPC (tonic) APIs, authentication, metrics, health, and
//! the process lifecycle that ties them to the store and the worker pool.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

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

/// Generated gRPC types and services (`crates/api/proto/segsplat/v1`), committed in
/// `src/generated/` and rewritten by `scripts/protogen.sh` when the proto changes.
pub mod proto {
    #![allow(clippy::all, missing_docs)]
    include!("generated/segsplat.v1.rs");

    /// Encoded file descriptors, for the gRPC reflection service.
    pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!("generated/segsplat_descriptor.bin");

    #[cfg(test)]
    mod tests {
        use segsplat_vision::models::store::sha256_file;

        /// The committed code says which proto it came from; a proto edited without running
        /// `scripts/protogen.sh` would otherwise build and serve the old messages.
        #[test]
        fn generated_grpc_code_is_from_the_proto_in_the_tree() {
            let proto = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("proto/segsplat/v1/segsplat.proto");
            let recorded = include_str!("generated/proto.sha256");
            let digest = sha256_file(&proto).expect("the proto is readable");
            assert_eq!(
                recorded.split_whitespace().next(),
                Some(digest.as_str()),
                "crates/api/proto changed since src/generated/ was written: run scripts/protogen.sh"
            );
        }
    }
}
