#!/usr/bin/env bash
# Installs what a fresh Debian machine lacks to build, test and run segsplat:
# - Mesa's software Vulkan driver (lavapipe) and the Vulkan loader, so the GPU engine runs without a GPU;
# - the Khronos Vulkan validation layer, under which scripts/sync_validation.sh checks every
#   barrier of the GPU tests' recordings;
# - the ONNX Runtime shared library (from the `onnxruntime` wheel) for the model runtime;
# - ffmpeg, which extracts frames from Neu3D camera videos (and makes the test videos);
# - s3rver (npm registry), the S3-compatible server the object-store tests run against, and
#   PostgreSQL (Debian's package), the database the Postgres store tests run against
#   (scripts/test_servers.sh starts both);
# - openapi-spec-validator, schemathesis and openapi-python-client (PyPI), which
#   scripts/contract.sh runs against the REST API's document and a live server (the last
#   generates a Python client whose trained-file downloads it checks);
# - Chromium (Debian's package) and playwright-core (npm), which scripts/console_e2e.sh uses to
#   test the web console in a real browser;
# - promtool (Debian's prometheus package, installed without its recommends), which
#   tests/deploy/observability.rs runs on the alert rules' unit tests.
# Idempotent: skips what is already there.
set -euo pipefail

need_apt=()
for package in mesa-vulkan-drivers libvulkan1 vulkan-validationlayers curl ffmpeg postgresql chromium; do
  dpkg -s "$package" >/dev/null 2>&1 || need_apt+=("$package")
done
# Node.js for s3rver, unless the machine has its own.
command -v npm >/dev/null 2>&1 || for package in nodejs npm; do
  dpkg -s "$package" >/dev/null 2>&1 || need_apt+=("$package")
done
if [ ${#need_apt[@]} -gt 0 ]; then
  sudo_cmd=""
  [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${need_apt[@]}"
fi
# promtool, from the prometheus package without its recommends (node-exporter and the like: only
# promtool is used). Checked by the command, so a machine with its own promtool is left alone.
if ! command -v promtool >/dev/null 2>&1; then
  sudo_cmd=""
  [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  [ ${#need_apt[@]} -gt 0 ] || $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends prometheus
fi

if command -v python3 >/dev/null 2>&1; then
  if ! python3 -c "import onnxruntime" >/dev/null 2>&1; then
    python3 -m pip install --quiet --disable-pip-version-check "onnxruntime>=1.20" \
      || echo "warning: could not install onnxruntime; model features will report it missing" >&2
  fi
fi

# The REST contract's tools (scripts/contract.sh), pinned: a newer schemathesis may bring new
# checks, which should arrive as a deliberate change here rather than as a red CI run.
pip_version() { python3 -m pip show "$1" 2>/dev/null | sed -n 's/^Version: //p'; }
if command -v python3 >/dev/null 2>&1; then
  if [ "$(pip_version openapi-spec-validator)" != "0.9.0" ] \
    || [ "$(pip_version schemathesis)" != "4.32.5" ] \
    || [ "$(pip_version openapi-python-client)" != "0.29.1" ]; then
    python3 -m pip install --quiet --disable-pip-version-check \
      "openapi-spec-validator==0.9.0" "schemathesis==4.32.5" "openapi-python-client==0.29.1" \
      || echo "warning: could not install the contract tools; scripts/contract.sh needs them in CI" >&2
  fi
fi

# cargo-fuzz for the short fuzz runs at the end of scripts/test.sh (docs/fuzzing.md), when a
# nightly toolchain is there to run it; without either, fuzz.sh says so and the stable corpus
# replay still runs.
if cargo +nightly --version >/dev/null 2>&1 && ! cargo fuzz --version >/dev/null 2>&1; then
  cargo install --quiet --locked cargo-fuzz@0.13.2 \
    || echo "warning: could not install cargo-fuzz; the fuzz runs will be skipped" >&2
fi

# The S3-compatible test server, pinned, in a tools folder outside the repository.
SEGSPLAT_TOOLS_DIR=${SEGSPLAT_TOOLS_DIR:-$HOME/.cache/segsplat-tools}
if [ ! -x "$SEGSPLAT_TOOLS_DIR/s3rver/node_modules/.bin/s3rver" ]; then
  mkdir -p "$SEGSPLAT_TOOLS_DIR/s3rver"
  npm install --silent --no-audit --no-fund --prefix "$SEGSPLAT_TOOLS_DIR/s3rver" s3rver@3.7.1 \
    || echo "warning: could not install s3rver; the object-store tests need it in CI" >&2
fi

# The browser-test driver for the web console (scripts/console_e2e.sh), pinned, beside s3rver.
# playwright-core brings no browser of its own: it drives Debian's chromium.
if [ ! -d "$SEGSPLAT_TOOLS_DIR/playwright/node_modules/playwright-core" ]; then
  mkdir -p "$SEGSPLAT_TOOLS_DIR/playwright"
  npm install --silent --no-audit --no-fund --prefix "$SEGSPLAT_TOOLS_DIR/playwright" playwright-core@1.65.1 \
    || echo "warning: could not install playwright-core; the console browser tests need it in CI" >&2
fi
