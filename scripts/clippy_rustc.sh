#!/bin/sh
# The compiler scripts/test.sh builds the workspace's own crates with (cargo's
# RUSTC_WORKSPACE_WRAPPER): clippy-driver, which is rustc plus clippy's lints, with warnings as
# errors, the same check as `cargo clippy --workspace --all-targets -- -D warnings`, but made
# while the test build compiles, so the dependencies are compiled once instead of also checked
# once more for a separate clippy run. Dependencies are not wrapped (they build with plain rustc).
#
# Cargo calls this as `clippy_rustc.sh RUSTC ARGS...`: clippy-driver comes from the same
# toolchain folder as RUSTC, and takes RUSTC as its first argument like any rustc wrapper.
driver="$(dirname "$1")/clippy-driver"
[ -x "$driver" ] || driver=clippy-driver
exec "$driver" "$@" -D warnings
