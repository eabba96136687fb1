#!/usr/bin/env bash
# The test command from the README: every test, on the software Vulkan adapter when there is no GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa warns on every device creation without it; harmless but noisy.
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
# wgpu asks for the Khronos validation layer in debug builds whenever it is installed (the
# bootstrap installs it for scripts/sync_validation.sh, below): off for the suite itself, which
# it would slow down.
export WGPU_VALIDATION=${WGPU_VALIDATION:-0}
# Two test threads through the environment, not `-- --test-threads=2`: the criterion benches
# (run once each in test mode) have their own argument parser and reject that flag.
export RUST_TEST_THREADS=${RUST_TEST_THREADS:-2}
# A CI machine builds from nothing and never again: incremental compilation's caches are only
# cost there (writing them, and the smaller code units it splits crates into).
if [ "${CI:-}" = true ]; then
    export CARGO_INCREMENTAL=${CARGO_INCREMENTAL:-0}
fi
# Each phase's start time and the disk left, so a slow or failed suite shows where its time
# (and its disk) went.
phase() { echo "== $(date +%H:%M:%S) $1 ($(df -h --output=avail . | tail -n 1 | tr -d ' ') free)"; }
export -f phase
# Formatting first: it needs no build.
phase "fmt"
if cargo fmt --version >/dev/null 2>&1; then
    cargo fmt --check
else
    echo "skipping cargo fmt --check: rustfmt is not installed"
fi
# Clippy with warnings as errors, on every target of the workspace's crates, as
# `cargo clippy --workspace --all-targets -- -D warnings` would: but as the compiler of those
# crates in the one test build below (scripts/clippy_rustc.sh), not as a run of its own, which
# checked every dependency a second time (13 of a run's 89 minutes on a 2-core machine).
# Exported, so every later cargo command here (and in contract.sh and console_e2e.sh) reuses
# that build instead of making another.
if cargo clippy --version >/dev/null 2>&1; then
    export RUSTC_WORKSPACE_WRAPPER="$PWD/scripts/clippy_rustc.sh"
else
    echo "skipping clippy: it is not installed (the build below runs plain rustc)"
fi
# The crates' dependency graph is the architecture: nothing reaches up a layer, and the engine
# side never pulls in tokio, axum, tonic or sqlx (docs/architecture.md).
phase "layers"
bash scripts/check_layers.sh
# Every target of every crate built once (and linted, above) before anything runs.
phase "build and clippy"
cargo test --locked --workspace --all-targets --no-run
# `.ci/run` stops here once, while scripts/bootstrap.sh installs the test servers beside the
# build, then runs this script whole (the build above is then a no-op).
if [ "${1:-}" = "--build-only" ]; then
    exit 0
fi
# The real servers the storage tests use (an S3-compatible one and PostgreSQL), on 127.0.0.1.
phase "test servers"
source scripts/test_servers.sh
# Benches first (one quick pass each, to prove they still run), then every test target, so the
# run ends on the test summary. `--bench '*'`, not `--benches`: that also selects the libraries
# and binaries (bench = true by default) and ran their unit tests a second time.
phase "benches"
cargo test --locked --workspace --bench '*'
# The REST contract and the web console run beside the tests, not after them: they are mostly a
# live server waiting on schemathesis and a browser (together 4m52s when they ran after the
# tests). Their output is kept and printed when the tests end.
# - contract: the REST contract against a live server: the served OpenAPI document validates, and
#   schemathesis finds no failures in a bounded run (scripts/contract.sh; skips without its
#   tools, except under CI=true).
# - console: the web console in a real browser: playwright-core driving Debian's chromium
#   headless against a live server, from upload to a text query's masks (scripts/console_e2e.sh;
#   skips without its tools, except under CI=true). Screenshots land in console-screenshots/.
phase "contract and console (beside the tests; their log follows the tests)"
live_checks_log=$(mktemp)
# Their own session (process group), so a failed test run stops them and their servers too.
setsid bash -c 'set -euo pipefail
    phase "contract"
    bash scripts/contract.sh
    phase "console"
    bash scripts/console_e2e.sh' >"$live_checks_log" 2>&1 &
live_checks=$!
# (test_servers.sh's own EXIT trap, which stops the storage servers, is kept in this one.)
trap 'kill -TERM -- "-$live_checks" 2>/dev/null || true; stop_test_servers' EXIT
# Every unit and integration test (`cargo test --workspace --lib --bins --tests`), the test
# binaries two at a time, longest first (scripts/run_tests.sh): one at a time, a binary's last
# long test left a core idle (390 s alone on two cores; two at a time 271 s).
phase "tests"
bash scripts/run_tests.sh
# The job and store tests again with every service on PostgreSQL instead of SQLite (each test
# gets a fresh database on the server test_servers.sh started), so both backends pass the same
# tests. `--workspace` keeps the feature set of the run above, so nothing is rebuilt.
phase "tests on PostgreSQL"
if [ -n "${SEGSPLAT_TEST_POSTGRES_URL:-}" ]; then
    SEGSPLAT_TEST_BACKEND=postgres cargo test --locked --workspace --test service --test service_workers
fi
# The GPU tests and short training runs again under the Khronos layer's synchronization
# validation: a missing barrier gives right answers on the software adapter, which runs a
# submission's commands one at a time, and wrong ones on a GPU (scripts/sync_validation.sh).
phase "synchronization validation"
if [ "${CI:-}" = true ] || [ -e /usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json ]; then
    bash scripts/sync_validation.sh --quick
else
    echo "skipping: the Khronos validation layer is not installed (apt-get install vulkan-validationlayers)"
fi
phase "waiting for contract and console"
live_status=0
wait "$live_checks" || live_status=$?
trap stop_test_servers EXIT
cat "$live_checks_log"
rm -f "$live_checks_log"
if [ "$live_status" -ne 0 ]; then
    echo "contract or console failed (exit $live_status): see its log above" >&2
    exit "$live_status"
fi

# Every fuzz target for a short bounded time on its committed corpus (docs/fuzzing.md). Needs
# nightly Rust and cargo-fuzz; without them fuzz.sh says so and skips, and the stable replay of
# the corpus in tests/fuzz_corpus.rs (above) is what guards the parsers.
# Its own workspace on nightly, never linted with clippy: not through the wrapper either.
phase "fuzz"
unset RUSTC_WORKSPACE_WRAPPER
bash scripts/fuzz.sh "${SEGSPLAT_FUZZ_SECONDS:-10}"
