#!/usr/bin/env bash
# A walk-through of the main job on the embedded defaults, as a user runs it: start
# `segsplat serve` (SQLite and a local blob dir, the best GPU or the software Vulkan adapter),
# upload a dataset, run Segment then Splat on it (masks from the dataset, else SAM when a model
# dir is configured, else the classical segmenter) with a progress bar per stage, then show the
# objects it found in a table, render the biggest object's mask for frame 0 and say where
# everything is.
#
#   bash scripts/demo.sh [DATASET_DIR] [STEPS]
#
# STEPS (500) trains that many steps at 256 px; "auto" trains at 256 px for the steps the job
# sizes from the scene; "defaults" runs the job exactly at its own defaults (steps from the
# scene, full resolution): the whole job as a user gets it.
# Without DATASET_DIR it uses ../shared/data/figurine when present, else a synthetic scene.
# Everything it writes (the service's data, the server log, the mask, the summary) goes into one
# folder, demo-output in the current directory unless SEGSPLAT_DEMO_OUT names another. SEGSPLAT_BIN=path/to/segsplat
# uses that binary as it is (no bootstrap, no build); otherwise the release build is made first.
# SEGSPLAT_DEMO_PORT picks the HTTP port (8080). SEGSPLAT_GEMM_KERNEL / SEGSPLAT_RASTER_KERNEL
# force the server's kernels as they do the one-shot commands'. The server stops when the demo ends, unless
# SEGSPLAT_DEMO_KEEP_SERVER=1 (or, on a terminal, the answer to the question at the end) keeps it
# running for the web console until Ctrl-C.
set -euo pipefail
case ${2:-500} in
  defaults|auto) ;;
  *[!0-9]*) echo "STEPS must be a number of steps, \"auto\" or \"defaults\", not '$2'" >&2; exit 2;;
esac
# Paths the caller gives are theirs: resolve them before moving to the repository.
caller=$(pwd)
absolute() { case $1 in /*) echo "$1";; *) echo "$caller/$1";; esac; }
cd "$(dirname "$0")/.."
if [ -n "${SEGSPLAT_BIN:-}" ]; then
  bin=$(absolute "$SEGSPLAT_BIN")
  [ -x "$bin" ] || { echo "SEGSPLAT_BIN=$bin is not an executable" >&2; exit 2; }
else
  bash scripts/bootstrap.sh
  cargo build --release --locked
  bin=target/release/segsplat
fi
out=$(absolute "${SEGSPLAT_DEMO_OUT:-demo-output}")
mkdir -p "$out"
out=$(cd "$out" && pwd)
http=127.0.0.1:${SEGSPLAT_DEMO_PORT:-8080}
dataset=${1:+$(absolute "$1")}
steps=${2:-500}
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
trap 'kill "${server:-}" 2>/dev/null || true; wait "${server:-}" 2>/dev/null || true' EXIT

if [ -z "$dataset" ]; then
  if [ -d ../shared/data/figurine ]; then dataset=../shared/data/figurine
  else dataset=$out/synthetic-scene; "$bin" synthetic-scene "$dataset" >/dev/null; fi
fi

# SEGSPLAT_GEMM_KERNEL / SEGSPLAT_RASTER_KERNEL force the one-shot commands' kernels; the server
# reads the same choice from workers.adapters.kernels, so the demo passes them on.
if [ -n "${SEGSPLAT_GEMM_KERNEL:-}" ]; then
  export SEGSPLAT_WORKERS__ADAPTERS__KERNELS__GEMM=$SEGSPLAT_GEMM_KERNEL
fi
if [ -n "${SEGSPLAT_RASTER_KERNEL:-}" ]; then
  export SEGSPLAT_WORKERS__ADAPTERS__KERNELS__RASTER=$SEGSPLAT_RASTER_KERNEL
fi
# The server's own log goes to a file, without colour codes, so the walk-through stays readable.
NO_COLOR=1 "$bin" serve --data-dir "$out/data" --http "$http" --grpc 127.0.0.1:0 \
  >"$out/server.log" 2>&1 &
server=$!
echo "segsplat serve started on http://$http (log: $out/server.log)"
for _ in $(seq 150); do
  curl -sf "http://$http/healthz" >/dev/null && break
  kill -0 "$server" 2>/dev/null || { echo "the server exited; see $out/server.log" >&2; exit 1; }
  sleep 0.2
done

python3 scripts/demo_walkthrough.py --url "http://$http" --dataset "$dataset" --steps "$steps" \
  --out "$out"

keep=${SEGSPLAT_DEMO_KEEP_SERVER:-}
if [ -z "$keep" ] && [ -t 0 ] && [ -t 1 ]; then
  read -r -p "Keep the server running to look at the result in the console? [y/N] " answer || answer=""
  case $answer in [yY]*) keep=1;; esac
fi
if [ "$keep" = 1 ]; then
  echo "the server keeps running on http://$http (the console is at http://$http/); Ctrl-C stops it"
  wait "$server" || true
else
  echo "stopping the server (SEGSPLAT_DEMO_KEEP_SERVER=1 keeps it running for the console)"
fi
