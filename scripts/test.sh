#!/usr/bin/env bash
# The test command from the README: every test, on the software Vulkan adapter when there is no GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --locked --all-targets -- --test-threads=2
