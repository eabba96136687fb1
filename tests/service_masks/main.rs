//! Masks and exports from a trained scene through the service: REST masks for a frame and for a
//! pose, visible-only masks, the PNG endpoint, per-object PLY, the labels sidecar, gRPC
//! `RenderMask`, and the errors a caller can act on. The scene is the synthetic three-sphere
//! capture with exact instance masks, so rendered masks are checked against the truth.
//!
//! - [`trained_scene`]: one trained scene asked for every mask and export, and the errors;
//! - [`local_commands`]: `segsplat export`, `eval --oracle` and `query` on the data dir the
//!   service wrote;
//! - [`grpc_deadline`]: the server's own DEADLINE_EXCEEDED, read over plain HTTP/2;
//! - [`truth`]: masks decoded from the answers, and the true masks they are checked against.

#[path = "../common/mod.rs"]
mod common;

mod grpc_deadline;
mod local_commands;
mod trained_scene;
mod truth;
