#!/usr/bin/env bash
# The test command from the README: every test, on the software Vulkan adapter when there is no GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa warns on every device creation without it; harmless but noisy.
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
cargo test --locked --all-targets -- --test-threads=2
