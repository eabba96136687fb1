//! The use cases REST, gRPC and the CLI share, typed and free of HTTP and gRPC types: each
//! interface parses its input, calls one of these, and maps the result and the error.

pub mod ingest;
pub mod job_bounds;
pub mod jobs;
pub mod objects;
pub mod observe;
pub mod query;
pub mod scenes;
pub mod serving;
pub mod workers;
