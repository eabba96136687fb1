//! The service's core from outside, through a real server on ephemeral ports with a CPU-only
//! test job kind: the use cases both protocols share, the job queue, tenants, uploads and the
//! object-store blob backend. `scripts/test.sh` runs this binary twice, on SQLite and on
//! PostgreSQL (`SEGSPLAT_TEST_BACKEND=postgres`).
//!
//! - [`usecases`]: the typed use cases called directly, without HTTP or gRPC;
//! - [`jobs`] and [`job_recovery`]: the durable job queue, and what survives dead workers,
//!   crashes and restarts;
//! - [`tenants`]: tokens, quotas and isolation across REST and gRPC;
//! - [`upload`] and [`upload_checks`]: every format accepted, every malformed upload refused
//!   without a trace;
//! - [`object_store`]: blobs in an S3-compatible store.
//!
//! `service_workers` stays a binary of its own: it reads process-wide cluster gauges from
//! `/metrics`, which another module's servers would change.

#[path = "../common/mod.rs"]
mod common;

mod job_recovery;
mod jobs;
mod object_store;
mod tenants;
mod upload;
mod upload_checks;
mod usecases;
