#!/usr/bin/env bash
# One device call that answers issue 38's open GPU questions, in order of what matters, inside a
# device session's time limit (a `run` of at most 600 s):
#  1. `scripts/gpu_check.sh run --skip-tests --job defaults`: the benches and the whole job at its
#     defaults (item 1's time, PSNR and SSIM; item 4's gpu_timeline and host figures; item 5's
#     mask seconds);
#  1b. the host's floor: the same plain bench on Vulkan and on wgpu's no-op device, this host's CPU;
#  2. the GPU tests but deform_gpu (gpu_check.sh, --test-timeout TT);
#  3. deform_gpu in parallel and with --test-threads=1, twice each: stop 54's wrong tiled GEMM
#     results on the H200 came from the uniform ring's cross-thread race fixed at stop 58 (the
#     binary now runs on a 16-slot ring), so every run should pass;
#  4. item 1's quality: the job through `segsplat serve` and scripts/schedule_check.py at more seeds
#     and with other steps and budgets, until 35 s are left.
#
# Run from the repository root, after `bash scripts/gpu_check.sh pack`, with the device tool:
#   run  carry [".gpu-pack"]  timeout_s 595  command "bash scripts/gpu_device_call.sh 2>&1"
# Try it first on the software adapter with tiny settings (about 45 s):
#   OUT=/tmp/trial-out TOTAL=1500 B1=600 EXTRA1="--skip-benches --timeout-scale 10" JOB=40 \
#   TESTS=gpu_scan TT=300 KEEP_AFTER_TESTS=300 \
#   VARIANTS='t1|1|{"steps": 30, "max_resolution": 128}' bash scripts/gpu_device_call.sh
# Settings (environment): TOTAL seconds for the whole call (570); B1 the budget of part 1 (190);
# JOB (defaults) and EXTRA1 for part 1; TESTS, TT (25) and KEEP_AFTER_TESTS (260) for part 2;
# VARIANTS, lines of name|seed|job config JSON, for part 4; DATA the dataset (the pack's).
# $OUT (the device tool's folder that comes back, 8 files at most) gets one session.tar.gz with
# every part's files, remade after each part, so a call cut short still brings back what finished.
set -u
cd "$(dirname "$0")/.."
start=$(date +%s)
total=${TOTAL:-570}
left() { echo $((total - ($(date +%s) - start))); }
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
# $OUT brings back 8 files at most: the session's own files live in $S and travel as one
# archive, remade after every part (a run cut short still brings back what finished).
S=/tmp/sess; rm -rf "$S"; mkdir -p "$S/variants" "$S/tests"
stamp() { echo "[$(( $(date +%s) - start )) s] $*" >>"$S/timeline.log"; tar -C "$S" -czf "$OUT/session.tar.gz" . 2>/dev/null; }

stamp "part 1: benches + job"
bash scripts/gpu_check.sh run --skip-tests --job "${JOB:-defaults}" --budget "${B1:-190}" --keep \
  ${EXTRA1:-} >"$S/check.log" 2>&1
stamp "part 1 rc=$?"
work=$(sed -n 's/^work folder kept: //p' "$S/check.log" | tail -1)
bin=$work/bin/bin/segsplat
[ -x "$bin" ] || bin=${SEGSPLAT_BIN:-}
# Where the loader needed pointing at the driver's Vulkan manifest, gpu_check.sh found it and
# noted it in the kept work folder.
if [ -f "$work/meta/vk_driver_files" ]; then
  VK_DRIVER_FILES=$(cat "$work/meta/vk_driver_files")
  export VK_DRIVER_FILES
fi
export XDG_RUNTIME_DIR=/tmp SEGSPLAT_BIN=$bin

data=${DATA:-$(ls -d .gpu-pack/data/* | head -1)}
stamp "part 1b: the host's floor (Vulkan against the no-op device, same flags, this host's CPU)"
for device in vulkan noop; do
  flag=""; [ "$device" = noop ] && flag=--noop-device
  timeout 60 "$bin" bench "$data" --steps 2000 --max-resolution 1000 --no-densify --seed 42 \
    --timing-repeats 1 --json $flag >"$S/floor-$device.json" 2>"$S/floor-$device.err"
  stamp "floor $device rc=$?"
done

stamp "part 2: tests"
t=$(( $(left) - ${KEEP_AFTER_TESTS:-260} ))
[ "$t" -gt 30 ] && OUT=$S/tests bash -c 'mkdir -p $OUT; bash scripts/gpu_check.sh run --skip-benches --skip-job \
  --tests '"${TESTS:-gpu_scan,gpu_sort,gpu_adam,gpu_loss,gpu_densify,object_batch_gpu,render_bands_gpu,object_step_batched,segment_then_splat_synthetic,train_synthetic,segment_then_splat_association,raster_gpu}"' \
  --test-timeout '"${TT:-25}"' --budget '"$t"' >$OUT/tests.log 2>&1'
stamp "part 2 done"

stamp "part 3: deform_gpu"
d=$work/bin/tests/deform_gpu
if [ -x "$d" ]; then
  {
    for i in 1 2; do echo "== parallel $i"; timeout 25 "$d" 2>&1 | grep -E "Tiled|Rows|Broadcast|test result|FAILED|panicked"; done
    for i in 1 2; do echo "== serial $i"; timeout 40 "$d" --test-threads=1 2>&1 | grep -E "Tiled|Rows|Broadcast|test result|FAILED|panicked"; done
  } >"$S/deform.log" 2>&1
else
  echo "no deform_gpu at $d" >"$S/deform.log"
fi
stamp "part 3 done"

stamp "part 4: job variants"
rm -rf /tmp/sc-data
"$bin" serve --data-dir /tmp/sc-data --http 127.0.0.1:18080 --grpc 127.0.0.1:0 >"$S/sc_server.log" 2>&1 &
server=$!
for _ in $(seq 100); do
  python3 -c 'import urllib.request; urllib.request.urlopen("http://127.0.0.1:18080/healthz")' 2>/dev/null && break
  sleep 0.2
done
# name|seed|config
default_variants='defaults-s1|1|{}
objloss0-s42|42|{"object_loss": {"weight": 0.0}}
budget264k-s42|42|{"gaussian_budget": 264000}
steps2000-s42|42|{"steps": 2000}
defaults-s2|2|{}
budget264k-s1|1|{"gaussian_budget": 264000}
budget66k-s42|42|{"gaussian_budget": 66000}
steps2000-s1|1|{"steps": 2000}'
variants=${VARIANTS:-$default_variants}
while IFS='|' read -r name seed config; do
  [ -z "$name" ] && continue
  t=$(( $(left) - 5 ))
  [ "$t" -lt 35 ] && { stamp "variant $name skipped: $t s left"; continue; }
  timeout "$t" python3 scripts/schedule_check.py --url http://127.0.0.1:18080 --dataset "$data" \
    --steps scene --seed "$seed" --held-out-every 500 --config "$config" \
    --json "$S/variants/$name.json" >>"$S/variants.log" 2>&1
  stamp "variant $name rc=$?"
done <<<"$variants"
kill $server 2>/dev/null; wait $server 2>/dev/null
rm -rf "$work"
stamp "done"
cat "$S/timeline.log"; cat "$S/deform.log"
python3 - "$S" <<'PY'
import json, glob, sys, os
for device in ("vulkan", "noop"):
    try:
        r = json.load(open(os.path.join(sys.argv[1], f"floor-{device}.json")))
        print("floor", device, round(r["steps_per_sec"], 1), r["dispatches_per_step"], json.dumps(r["host"]))
    except Exception as error:
        print("floor", device, "missing:", error)
for f in sorted(glob.glob(os.path.join(sys.argv[1], "variants", "*.json"))):
    for job in json.load(open(f)).get("jobs", []):
        curve = " ".join(f"{p[0]}:{p[1]:.2f}" for p in job.get("curve", []))
        print(os.path.basename(f), job.get("steps"), job.get("held_out_psnr"), job.get("held_out_ssim"),
              job.get("training_seconds"), curve)
PY
