#!/usr/bin/env bash
# The web console in a real browser (docs/console.md, "Tests"): starts `segsplat serve` on
# 127.0.0.1 with a bearer token and the tiny test models, writes a synthetic scene with known
# objects, and runs tests/console/console_e2e.mjs (playwright-core driving Debian's chromium
# headless) through upload, a short segment_then_splat job, the 3D view, a text query, the mask
# overlay and a per-object PLY download. Screenshots go to console-screenshots/ (or
# SEGSPLAT_CONSOLE_SHOTS), which CI keeps as artifacts.
#
# Without chromium or playwright-core (scripts/bootstrap.sh installs both) the script says so and
# skips, except under CI=true, where a missing tool fails.
set -euo pipefail
cd "$(dirname "$0")/.."

tools=${SEGSPLAT_TOOLS_DIR:-$HOME/.cache/segsplat-tools}
playwright_dir="$tools/playwright/node_modules/playwright-core"
chromium=${SEGSPLAT_CHROMIUM:-$(command -v chromium || true)}
missing=""
[ -n "$chromium" ] || missing="chromium (Debian's package)"
[ -d "$playwright_dir" ] || missing="${missing:+$missing and }playwright-core (npm)"
command -v node >/dev/null 2>&1 || missing="${missing:+$missing and }node"
if [ -n "$missing" ]; then
  if [ "${CI:-}" = "true" ]; then
    echo "console e2e: $missing is missing (scripts/bootstrap.sh installs it)" >&2
    exit 1
  fi
  echo "skipping the console browser tests: $missing is not installed (scripts/bootstrap.sh installs it)"
  exit 0
fi

# The binary as the tests build it (the same features, so after scripts/test.sh's test phase
# nothing is rebuilt).
if [ -z "${SEGSPLAT_BIN:-}" ]; then
  cargo test --locked --workspace --no-run --test console_serving
fi
binary=${SEGSPLAT_BIN:-target/debug/segsplat}
shots=${SEGSPLAT_CONSOLE_SHOTS:-console-screenshots}
rm -rf "$shots"
mkdir -p "$shots"

LIVE_TOKEN_PREFIX=console source scripts/live_server.sh

# A small synthetic scene: three coloured spheres with masks at every level, which the tiny
# CLIP model tells apart by colour ("red", "green", "blue").
"$binary" synthetic-scene "$work/scene" --frames 9 --width 96 --height 72 >/dev/null
(cd "$work/scene" && python3 -m zipfile -c "$work/scene.zip" .)
# The same scene without its masks: a job that asks for the user's masks fails on it.
(cd "$work/scene" && python3 -m zipfile -c "$work/no-masks.zip" images sparse)
echo "this is not an archive" >"$work/not-a-scene.zip"
# Moving spheres in the D-NeRF layout (a time per frame), for the time slider.
"$binary" synthetic-scene "$work/moving" --dynamic --frames 12 --width 64 --height 48 >/dev/null
(cd "$work/moving" && python3 -m zipfile -c "$work/moving.zip" .)

live_server_start "console e2e" "$binary" \
  SEGSPLAT_AUTH__TOKENS="[\"$token\"]" \
  SEGSPLAT_MODELS__DIR="$PWD/tests/fixtures/models/tiny" \
  SEGSPLAT_CONSOLE__GRAFANA_URL="http://127.0.0.1:3000/d/segsplat"

status=0
SEGSPLAT_PLAYWRIGHT="$playwright_dir" \
SEGSPLAT_URL="$base" \
SEGSPLAT_TOKEN="$token" \
SEGSPLAT_SCENE_ZIP="$work/scene.zip" \
SEGSPLAT_BAD_UPLOAD="$work/not-a-scene.zip" \
SEGSPLAT_NO_MASKS_ZIP="$work/no-masks.zip" \
SEGSPLAT_DYNAMIC_ZIP="$work/moving.zip" \
SEGSPLAT_CHROMIUM="$chromium" \
SEGSPLAT_CONSOLE_SHOTS="$shots" \
SEGSPLAT_DOWNLOADS="$work/downloads" \
  node tests/console/console_e2e.mjs || status=$?
if [ "$status" -ne 0 ]; then
  echo "console e2e: failed (server log follows)" >&2
  tail -n 50 "$work/server.log" >&2
  exit "$status"
fi
echo "console e2e: passed; screenshots in $shots/"
