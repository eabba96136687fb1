//! What can be checked of `deploy/` without docker, a cluster or a container registry (none
//! exists on these machines), one module per thing deployed:
//!
//! - [`image`]: the Dockerfile's settings, ports, binary and commands are the service's;
//! - [`compose`] and [`kubernetes`]: every file parses; kustomizations name files that exist;
//!   every `SEGSPLAT_*` variable is a configuration key and the settings load; ports, probes
//!   and scrape targets are the ones the settings make the service listen on; the commands
//!   and flags exist in the built binary; and the objects refer to each other correctly (HPA
//!   target, PDB and Service selectors, generated ConfigMap and Secret names, GPU request);
//! - [`tools`]: where `kubectl` is installed, the overlay is also rendered by kustomize, and
//!   where `kubernetes-validate` is, the rendered objects are checked against the Kubernetes
//!   schemas;
//! - [`observability`]: every metric the dashboard and the alert rules name is on a running
//!   service's `/metrics`, and the alert rules pass promtool's unit tests.
//!
//! [`files`] reads the deploy files; [`settings`] checks variables against the service's
//! configuration and commands against the binary.

#[path = "../common/mod.rs"]
mod common;

mod compose;
mod files;
mod image;
mod kubernetes;
mod observability;
mod settings;
mod tools;
