//! The service core: the store (database and blobs), jobs and their workers, the job kinds,
//! the serving cache for trained scenes, the use cases REST, gRPC and the CLI share, and the
//! service config that composes every crate's options. No HTTP or gRPC types.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

pub mod config;
pub mod core;
pub mod job_kinds;
pub mod jobs;
pub mod serving;
pub mod store;
pub mod usecases;
