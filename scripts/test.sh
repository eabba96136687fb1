#!/usr/bin/env bash
# The test command from the README: every test, on the software Vulkan adapter when there is no GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa warns on every device creation without it; harmless but noisy.
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
# Two test threads through the environment, not `-- --test-threads=2`: the criterion benches
# (run once each in test mode) have their own argument parser and reject that flag.
export RUST_TEST_THREADS=${RUST_TEST_THREADS:-2}
# Each phase's start time, so a slow suite shows where its time goes.
phase() { echo "== $(date +%H:%M:%S) $1"; }
# Lints before anything is built for tests: formatting, then clippy with warnings as errors.
phase "fmt"
if cargo fmt --version >/dev/null 2>&1; then
    cargo fmt --check
else
    echo "skipping cargo fmt --check: rustfmt is not installed"
fi
phase "clippy"
if cargo clippy --version >/dev/null 2>&1; then
    cargo clippy --locked --workspace --all-targets -- -D warnings
else
    echo "skipping cargo clippy: clippy is not installed"
fi
# The crates' dependency graph is the architecture: nothing reaches up a layer, and the engine
# side never pulls in tokio, axum, tonic or sqlx (docs/architecture.md).
phase "layers"
bash scripts/check_layers.sh
# The real servers the storage tests use (an S3-compatible one and PostgreSQL), on 127.0.0.1.
phase "test servers"
source scripts/test_servers.sh
# Benches first (one quick pass each, to prove they still run), then every test target, so the
# run ends on the test summary.
phase "benches"
cargo test --locked --workspace --benches
phase "tests"
cargo test --locked --workspace --lib --bins --tests
# The job and store tests again with every service on PostgreSQL instead of SQLite (each test
# gets a fresh database on the server test_servers.sh started), so both backends pass the same
# tests. `--workspace` keeps the feature set of the run above, so nothing is rebuilt.
phase "tests on PostgreSQL"
if [ -n "${SEGSPLAT_TEST_POSTGRES_URL:-}" ]; then
    SEGSPLAT_TEST_BACKEND=postgres cargo test --locked --workspace --test service_jobs --test service_core \
        --test service_tenants --test service_workers --test service_upload \
        --test service_object_store
fi
# The REST contract against a live server: the served OpenAPI document validates, and
# schemathesis finds no failures in a bounded run (scripts/contract.sh; skips without its tools,
# except under CI=true).
phase "contract"
bash scripts/contract.sh
# The web console in a real browser: playwright-core driving Debian's chromium headless against
# a live server, from upload to a text query's masks (scripts/console_e2e.sh; skips without its
# tools, except under CI=true). Screenshots land in console-screenshots/.
phase "console"
bash scripts/console_e2e.sh

# Every fuzz target for a short bounded time on its committed corpus (docs/fuzzing.md). Needs
# nightly Rust and cargo-fuzz; without them fuzz.sh says so and skips, and the stable replay of
# the corpus in tests/fuzz_corpus.rs (above) is what guards the parsers.
phase "fuzz"
bash scripts/fuzz.sh "${SEGSPLAT_FUZZ_SECONDS:-10}"
