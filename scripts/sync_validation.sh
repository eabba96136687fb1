#!/usr/bin/env bash
# The GPU tests and short training runs under the Khronos Vulkan validation layer with its
# synchronization validation on: every barrier wgpu derives from our recordings checked against
# what each command reads and writes.
#
# Why: the software adapter (lavapipe) runs a submission's commands one after another, so a
# missing barrier between two dispatches, or a copy racing a kernel, gives right answers there
# and wrong ones on a GPU that overlaps them. The layer finds such hazards on any adapter,
# lavapipe included. The layer's findings reach us through wgpu's log (`wgpu_hal`), so every
# run here logs to stderr and the logs are searched.
#
#   bash scripts/sync_validation.sh [--quick]
#
# --quick (what scripts/test.sh runs) checks the kernel tests and the short training runs below,
# and leaves out the three whole-training test binaries (train_synthetic, train_dynamic,
# segment_then_splat_synthetic: three minutes under the layer on two cores); the training runs
# cover the same steps (densification, the object loss, the deformation field).
# Needs the layer (Debian: `apt-get install vulkan-validationlayers`); exits 2 without it.
# Where a C compiler and the Vulkan headers are, it first checks that the layer reports a hazard
# planted on purpose (scripts/sync_hazard_control.c).
# Debian 12's layer (1.3.239) predates the SPIR-V source language naga writes for WGSL and
# reports every shader module as `InconsistentSpirv`; that one message is not counted.
set -euo pipefail
cd "$(dirname "$0")/.."

quick=0
for arg; do
  case $arg in
    --quick) quick=1 ;;
    -h | --help) sed -n '2,22p' "$0"; exit 0 ;;
    *) echo "unknown argument '$arg' (see --help)" >&2; exit 2 ;;
  esac
done

layer_found=0
for dir in /usr/share/vulkan/explicit_layer.d /usr/local/share/vulkan/explicit_layer.d \
  /etc/vulkan/explicit_layer.d "${HOME:-/nonexistent}/.local/share/vulkan/explicit_layer.d"; do
  [ -e "$dir/VkLayer_khronos_validation.json" ] && layer_found=1
done
if [ $layer_found = 0 ]; then
  echo "sync_validation: the Khronos validation layer is not installed" \
    "(Debian: apt-get install vulkan-validationlayers)" >&2
  exit 2
fi

export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
# wgpu turns the layer on; the layer turns synchronization validation on.
export WGPU_VALIDATION=1
export VK_LAYER_ENABLES=VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT
export RUST_LOG=wgpu_hal=warn,wgpu_core=warn
export RUST_TEST_THREADS=${RUST_TEST_THREADS:-2}

logs=$(mktemp -d)
trap 'rm -rf "$logs"' EXIT

source scripts/lanes.sh

# Longest first (two at a time below, so nothing long starts last).
tests=(gpu_loss gpu_adam gpu_sort object_batch_gpu deform_gpu object_step_batched render_bands_gpu
  raster_gpu gpu_scan gpu_densify)
[ $quick = 1 ] || tests=(train_dynamic segment_then_splat_synthetic train_synthetic "${tests[@]}")

# `--workspace` on every cargo command, as scripts/test.sh builds: the same features, so the
# build the suite made is reused.
bin=target/debug/segsplat
[ -x "$bin" ] || cargo build --locked --quiet --workspace --bin segsplat
static_scene=$logs/static-scene dynamic_scene=$logs/dynamic-scene
"$bin" synthetic-scene "$static_scene" --frames 16 --width 96 --height 72 >/dev/null
"$bin" synthetic-scene "$dynamic_scene" --dynamic --frames 16 --width 96 --height 72 >/dev/null

# The layer must really be loaded, or the search below finds nothing for the wrong reason.
VK_LOADER_DEBUG=layer "$bin" bench "$static_scene" --steps 2 --timing-repeats 1 --json \
  >"$logs/loader.log" 2>&1 || true
if ! grep -q 'Insert instance layer "VK_LAYER_KHRONOS_validation"' "$logs/loader.log"; then
  echo "sync_validation: the Vulkan loader did not load VK_LAYER_KHRONOS_validation:" >&2
  tail -20 "$logs/loader.log" >&2
  exit 1
fi
rm "$logs/loader.log"

# The positive control, where the Vulkan headers are (Debian's libvulkan-dev; CI has none): two
# fills of one buffer with no barrier between them must be reported (scripts/sync_hazard_control.c).
if command -v cc >/dev/null && [ -e /usr/include/vulkan/vulkan.h ]; then
  cc scripts/sync_hazard_control.c -lvulkan -o "$logs/control"
  VK_INSTANCE_LAYERS=VK_LAYER_KHRONOS_validation "$logs/control" >"$logs/control.out" 2>&1 || true
  if ! grep -q 'SYNC-HAZARD-WRITE-AFTER-WRITE' "$logs/control.out"; then
    echo "sync_validation: the layer did not report the control's unbarriered fills:" >&2
    tail -20 "$logs/control.out" >&2
    exit 1
  fi
  rm "$logs/control.out"
  echo "== the control's unbarriered fills are reported (SYNC-HAZARD-WRITE-AFTER-WRITE)"
else
  echo "== no positive control here (it needs cc and the Vulkan headers, libvulkan-dev)"
fi

# The training runs first: they take longest. Each kernel variant the adapter has; the plain
# runs densify (the synthetic scene grows from 1144 to 2151 Gaussians). The dynamic runs start
# from 1100 random Gaussians, not the scene's 5000, and measure the GEMM rate over 1100 rows, not
# the report's 16,384: the same dispatches (1100 rows split the weight gradients in two, as more
# would), and the tiled kernel, 0.2-0.4 GFLOP/s on lavapipe, took 65-70 s of the phase's 111 s
# with 5000 (16-17 s now).
for gemm in tiled rows broadcast; do
  lane_job "bench-deformation-$gemm" env SEGSPLAT_GEMM_KERNEL=$gemm "$bin" bench "$dynamic_scene" \
    --steps 4 --timing-repeats 1 --deformation --field-depth 4 --field-width 80 \
    --init-random 1100 --matmul-rows 1100 --json
done
for raster in pixels columns; do
  lane_job "bench-plain-$raster" env SEGSPLAT_RASTER_KERNEL=$raster "$bin" bench "$static_scene" \
    --steps 250 --timing-repeats 1 --json
done
lane_job bench-object-loss "$bin" bench "$static_scene" --steps 120 --timing-repeats 1 --object-loss \
  --json
for name in "${tests[@]}"; do
  lane_job "test-$name" cargo test --locked --workspace --test "$name"
done
echo "== GPU tests and training runs under synchronization validation, two at a time"
lanes_run 2 "$logs" failures || true
failures=()
[ ! -e "$logs/failed" ] || mapfile -t failures <"$logs/failed"

# A variant the adapter cannot run fails its bench with a message naming it: not a hazard.
findings=$(grep -h 'VALIDATION \[' "$logs"/*.log | grep -v 'InconsistentSpirv' | sort | uniq -c |
  sort -rn || true)
hazards=$(cat "$logs"/*.log | grep -c 'SYNC-HAZARD' || true)
echo "== $hazards synchronization hazards; other validation messages: ${findings:-none}"
if [ -n "$findings" ]; then
  grep -h -A2 'VALIDATION \[' "$logs"/*.log | grep -v 'InconsistentSpirv' | head -60
fi
if [ ${#failures[@]} -gt 0 ] || [ -n "$findings" ]; then
  [ ${#failures[@]} -eq 0 ] || echo "failed under the layer: ${failures[*]}" >&2
  exit 1
fi
