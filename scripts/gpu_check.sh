#!/usr/bin/env bash
# One command for a GPU. A GPU host is lent for minutes, with no Rust toolchain and no package
# registry, and receives only the working tree (plus ignored folders named to travel with it).
# So the binaries are built here and travel as a pack; there one command runs the GPU tests, the
# benchmarks and the whole job, and writes one JSON report.
#
#   bash scripts/gpu_check.sh pack                     # here: build, strip, compress into .gpu-pack/
#   bash scripts/gpu_check.sh run [OPTIONS] [DATASET]  # on the GPU host: everything, one report
#   bash scripts/gpu_check.sh run --dry-run [OPTIONS]  # the plan and the report's shape, nothing run
#
# `bash scripts/gpu_check.sh --help` lists the options; docs/benchmarks.md ("One command for a
# GPU") says how a session uses it.
set -euo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)
pack_dir=${SEGSPLAT_GPU_PACK:-$repo/.gpu-pack}
# What a device call may carry: the working tree and the pack together (device README).
limit_bytes=$((64 * 1024 * 1024))
# The test binaries that need an adapter: the engine's kernels against their CPU references,
# training on synthetic scenes, and the Segment-then-Splat end-to-end tests.
gpu_tests=(raster_gpu render_bands_gpu object_batch_gpu gpu_adam gpu_loss gpu_scan gpu_sort gpu_densify
  deform_gpu object_step_batched train_synthetic train_dynamic segment_then_splat_synthetic
  segment_then_splat_association)
# The Vulkan loader and the GL dispatch libraries NVIDIA's Vulkan driver links against; the GPU
# image has neither (device README).
loader_debs=(libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)

usage() {
  cat <<'EOF'
Usage:
  bash scripts/gpu_check.sh pack [--dataset DIR]
      Build the release binary and the GPU test binaries (release profile), strip them, compress
      them into .gpu-pack/binaries.tar.xz, download the Vulkan loader .debs into .gpu-pack/debs,
      copy the dataset (../shared/data/figurine) into .gpu-pack/data/, and check that the pack
      and the working tree together fit a device call (64 MiB). SEGSPLAT_GPU_PACK names another
      folder.

  bash scripts/gpu_check.sh run [OPTIONS] [DATASET_DIR]
      On the GPU host: unpack the Vulkan loader when the system has none, list the adapters, run
      every packed test binary, the benchmarks and the whole segment_then_splat job through the
      service (scripts/demo.sh), each with a timeout, a failure recorded without stopping the
      rest. Writes one JSON report to $OUT/gpu_check.json when OUT is set (and the step logs to
      $OUT/gpu_check_logs.tar.gz), else ./gpu-check-report.json. Exits 0 when every step passed,
      1 otherwise. DATASET_DIR defaults to ../shared/data/figurine, shared/data/figurine, the
      pack's dataset, else a synthetic scene.

Options of run:
  --quick              bench steps x 0.25, tests 60 s each, the job at 2000 steps (256 px) instead
                       of its defaults, budget 450 s
  --scale F            multiply every bench's steps by F (at least 5 steps each)
  --budget S           seconds for the whole run (default 560, --quick 450): every step's timeout
                       is cut to what is left, and a step with under 20 s left is skipped
  --timeout-scale F    multiply every step's own timeout by F (slow adapters)
  --test-timeout S     seconds per test binary (default 120)
  --tests A,B          run only these packed test binaries
  --job STEPS|defaults the job's steps at 256 px, or its own defaults (default: defaults)
  --skip-tests, --skip-benches, --skip-job
  --pack DIR           the pack folder (default .gpu-pack)
  --report FILE        where to write the report
  --keep               keep the work folder (binaries, logs, the job's data)
  --dry-run            run nothing: print the plan and write the report with every step skipped
EOF
}

die() {
  echo "gpu_check: $*" >&2
  exit 2
}

# ---------------------------------------------------------------------------------------------
# pack

tree_bytes() {
  # What a device call sends besides the pack: tracked and untracked-not-ignored files.
  (cd "$repo" && git ls-files -z -co --exclude-standard) | python3 -c '
import os, sys
names = sys.stdin.buffer.read().split(b"\0")
print(sum(os.path.getsize(n) for n in names if n and os.path.isfile(n)))'
}

mib() { awk -v b="$1" 'BEGIN { printf "%.1f MiB", b / 1048576 }'; }

# executables CARGO_JSON TEST NAME...: "name path" of each named target's executable in cargo's
# JSON messages (test harnesses when TEST is true, else binaries); fails naming any not found.
executables() {
  python3 - "$@" <<'EOF'
import json, sys
messages, test, wanted, found = sys.argv[1], sys.argv[2] == "true", set(sys.argv[3:]), {}
for line in open(messages):
    try:
        message = json.loads(line)
    except ValueError:
        continue
    target = message.get("target") or {}
    if (message.get("reason") == "compiler-artifact" and message.get("executable")
            and message.get("profile", {}).get("test") == test and target.get("name") in wanted):
        found[target["name"]] = message["executable"]
missing = sorted(wanted - found.keys())
if missing:
    sys.exit("no executable for: " + ", ".join(missing))
for name in sorted(found):
    print(name, found[name])
EOF
}

pack() {
  local dataset=$repo/../shared/data/figurine
  while [ $# -gt 0 ]; do
    case $1 in
      --dataset) dataset=${2:?--dataset needs a folder}; shift ;;
      -h | --help) usage; exit 0 ;;
      *) die "pack takes only --dataset DIR (got '$1')" ;;
    esac
    shift
  done
  command -v cargo >/dev/null || die "pack needs cargo (it builds the binaries)"
  cd "$repo"
  local stage
  stage=$(mktemp -d "${TMPDIR:-/tmp}/gpu-pack.XXXXXX")
  # shellcheck disable=SC2064 # the folder is known now and must go whatever happens later
  trap "rm -rf '$stage'" EXIT

  echo "== building the release binary and the GPU test binaries"
  # Cargo's own messages say where each executable is (CARGO_TARGET_DIR or not).
  cargo build --release --locked --message-format=json-render-diagnostics >"$stage/build.json"
  local test_args=()
  for name in "${gpu_tests[@]}"; do test_args+=(--test "$name"); done
  # Release, not dev: the test binaries then reuse the release build's dependencies (one build
  # of the tree instead of two on a 2-core machine), and the GPU runs them at full speed.
  cargo test --release --locked --no-run --message-format=json-render-diagnostics \
    "${test_args[@]}" >"$stage/tests.json"
  executables "$stage/build.json" false segsplat >"$stage/binary"
  executables "$stage/tests.json" true "${gpu_tests[@]}" >"$stage/executables"

  echo "== stripping and compressing"
  mkdir -p "$stage/pack/bin" "$stage/pack/tests" "$pack_dir"
  strip -o "$stage/pack/bin/segsplat" "$(cut -d' ' -f2- "$stage/binary")"
  local name path
  while read -r name path; do
    strip -o "$stage/pack/tests/$name" "$path"
  done <"$stage/executables"
  du -sh "$stage/pack/bin" "$stage/pack/tests"
  # One solid stream with a dictionary larger than any binary: the test binaries share most of
  # their code (wgpu, naga, the engine), which then compresses once.
  tar -C "$stage/pack" -cf - bin tests |
    xz -T1 --lzma2=preset=9,dict=256MiB >"$pack_dir/binaries.tar.xz.partial"
  mv "$pack_dir/binaries.tar.xz.partial" "$pack_dir/binaries.tar.xz"

  echo "== the Vulkan loader .debs"
  local lists=${TMPDIR:-/tmp}/segsplat-gpu-apt-lists
  mkdir -p "$lists/partial" "$pack_dir/debs"
  # amd64 whatever this machine is (the GPU hosts are x86-64), our own lists so the system's
  # are untouched, and no sandbox user so it works as root.
  local apt=(-q -oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists"
    -oAPT::Sandbox::User=root)
  if apt-get "${apt[@]}" update >"$stage/apt.log" 2>&1 &&
    (cd "$stage" && apt-get "${apt[@]}" download "${loader_debs[@]}" >>"$stage/apt.log" 2>&1); then
    rm -f "$pack_dir"/debs/*.deb
    mv "$stage"/*.deb "$pack_dir/debs/"
  elif compgen -G "$pack_dir/debs/*.deb" >/dev/null; then
    echo "apt-get failed; keeping the .debs already in $pack_dir/debs:" >&2
    tail -5 "$stage/apt.log" >&2
  else
    cat "$stage/apt.log" >&2
    die "could not download the Vulkan loader .debs"
  fi
  ls "$pack_dir/debs"

  # The benchmarks' dataset lives beside the checkout, which a device call does not send.
  rm -rf "$pack_dir/data"
  if [ -d "$dataset" ]; then
    echo "== the dataset $dataset"
    mkdir -p "$pack_dir/data"
    cp -r "$dataset" "$pack_dir/data/$(basename "$dataset")"
  else
    echo "no dataset at $dataset: the run will use a synthetic scene unless given one" >&2
  fi

  python3 - "$pack_dir/manifest.json" "$stage/executables" <<EOF
import json, os, platform, sys, time
names = [line.split()[0] for line in open(sys.argv[2]) if line.strip()]
manifest = {
    "commit": "$(git rev-parse HEAD)",
    "uncommitted_changes": $([ -z "$(git status --porcelain --untracked-files=no)" ] && echo False || echo True),
    "built_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    "profile": "release",
    # The GPU host's C library must be at least as new as this one.
    "built_on": platform.freedesktop_os_release().get("PRETTY_NAME", "?") + ", glibc "
    + platform.libc_ver()[1],
    "segsplat": "bin/segsplat",
    "tests": names,
    "loader_debs": sorted(os.listdir("$pack_dir/debs")),
    "datasets": sorted(os.listdir("$pack_dir/data")) if os.path.isdir("$pack_dir/data") else [],
}
with open(sys.argv[1], "w") as file:
    json.dump(manifest, file, indent=2)
    file.write("\n")
EOF

  local pack_bytes tree
  pack_bytes=$(du -sb "$pack_dir" | cut -f1)
  tree=$(tree_bytes)
  echo "== pack: $pack_dir"
  du -sh "$pack_dir"/* | sed 's/^/   /'
  echo "pack $(mib "$pack_bytes") ($pack_bytes bytes); working tree $(mib "$tree");" \
    "together $(mib $((pack_bytes + tree))) of the $(mib "$limit_bytes") a device call carries"
  if [ "$pack_bytes" -gt "$limit_bytes" ]; then
    die "the pack is over $(mib "$limit_bytes")"
  fi
  if [ $((pack_bytes + tree)) -gt "$limit_bytes" ]; then
    die "the pack and the working tree together are over $(mib "$limit_bytes")"
  fi
  echo "On the GPU host (device run, carry [\"${pack_dir#"$repo"/}\"]):  bash scripts/gpu_check.sh run --quick"
}

# ---------------------------------------------------------------------------------------------
# run

now() { date +%s; }

run() {
  # Not local: the step helpers and the exit trap read them.
  quick=0 scale="" budget="" timeout_scale=1 test_timeout="" only_tests="" job_steps=""
  skip_tests=0 skip_benches=0 skip_job=0 dry_run=0 keep=0 report="" dataset=""
  while [ $# -gt 0 ]; do
    case $1 in
      --quick) quick=1 ;;
      --scale) scale=${2:?--scale needs a number}; shift ;;
      --budget) budget=${2:?--budget needs seconds}; shift ;;
      --timeout-scale) timeout_scale=${2:?--timeout-scale needs a number}; shift ;;
      --test-timeout) test_timeout=${2:?--test-timeout needs seconds}; shift ;;
      --tests) only_tests=${2:?--tests needs names}; shift ;;
      --job) job_steps=${2:?--job needs STEPS or defaults}; shift ;;
      --skip-tests) skip_tests=1 ;;
      --skip-benches) skip_benches=1 ;;
      --skip-job) skip_job=1 ;;
      --pack) pack_dir=${2:?--pack needs a folder}; shift ;;
      --report) report=${2:?--report needs a file}; shift ;;
      --keep) keep=1 ;;
      --dry-run) dry_run=1 ;;
      -h | --help) usage; exit 0 ;;
      -*) die "unknown option '$1' (see --help)" ;;
      *)
        [ -z "$dataset" ] || die "one DATASET_DIR only (got '$dataset' and '$1')"
        dataset=$1
        ;;
    esac
    shift
  done
  local number='^[0-9]+([.][0-9]+)?$'
  [[ -z $scale || $scale =~ $number ]] || die "--scale must be a number, not '$scale'"
  [[ $timeout_scale =~ $number ]] || die "--timeout-scale must be a number, not '$timeout_scale'"
  [[ -z $budget || $budget =~ ^[0-9]+$ ]] || die "--budget must be whole seconds, not '$budget'"
  [[ -z $test_timeout || $test_timeout =~ ^[0-9]+$ ]] ||
    die "--test-timeout must be whole seconds, not '$test_timeout'"
  case ${job_steps:-defaults} in
    defaults) ;;
    *[!0-9]*) die "--job takes a number of steps or \"defaults\", not '$job_steps'" ;;
  esac
  command -v python3 >/dev/null || die "run needs python3 (the report and the demo use it)"
  # The interpreter itself rather than a version manager's shim, which costs more than the
  # report it runs, once per step.
  python=$(python3 -c 'import sys; print(sys.executable)')
  if [ $quick = 1 ]; then
    scale=${scale:-0.25} budget=${budget:-450} test_timeout=${test_timeout:-60}
    job_steps=${job_steps:-2000}
  fi
  scale=${scale:-1} budget=${budget:-560} test_timeout=${test_timeout:-120}
  job_steps=${job_steps:-defaults}
  # Paths the caller gives are theirs; the steps run from the repository (the test binaries
  # read fixtures relative to it, as under cargo).
  local caller
  caller=$(pwd)
  absolute() { case $1 in /*) echo "$1" ;; *) echo "$caller/$1" ;; esac }
  [ -z "$dataset" ] || dataset=$(absolute "$dataset")
  pack_dir=$(absolute "$pack_dir")
  if [ -n "$report" ]; then report=$(absolute "$report")
  elif [ -n "${OUT:-}" ]; then report=$OUT/gpu_check.json
  else report=$caller/gpu-check-report.json
  fi
  cd "$repo"

  start=$(now)
  work=$(mktemp -d "${TMPDIR:-/tmp}/gpu-check.XXXXXX")
  mkdir -p "$work/meta" "$work/steps"
  step_index=0 reserve=10 failures=0
  finish() {
    meta wall_seconds "$(($(now) - start))"
    write_report --summary || true
    if [ -n "${OUT:-}" ] && [ -d "$work/steps" ]; then
      local logs=(steps meta) file
      for file in demo/server.log demo/summary.txt; do [ ! -f "$work/$file" ] || logs+=("$file"); done
      tar -czf "$OUT/gpu_check_logs.tar.gz" -C "$work" "${logs[@]}" || true
    fi
    echo "report: $report"
    if [ "$keep" = 1 ]; then echo "work folder kept: $work"; else rm -rf "$work"; fi
  }
  trap finish EXIT

  meta started_at "$(date -u +%Y-%m-%dT%H:%M:%SZ)"
  meta finished false
  meta quick "$([ $quick = 1 ] && echo true || echo false)"
  meta dry_run "$([ $dry_run = 1 ] && echo true || echo false)"
  meta scale "$scale"
  meta budget_seconds "$budget"
  meta timeout_scale "$timeout_scale"
  meta host "$(hostname 2>/dev/null || echo unknown), $(nproc) CPUs"
  if command -v nvidia-smi >/dev/null; then
    meta gpu "$(timeout 20 nvidia-smi --query-gpu=name,driver_version,memory.total \
      --format=csv,noheader 2>&1 | head -3 || true)"
  fi
  write_report

  # The binaries: from the pack, else (no tests then) the CLI that SEGSPLAT_BIN names.
  bin="" tests_dir=$work/bin/tests packed_tests=() pack_note=""
  if [ -f "$pack_dir/manifest.json" ]; then
    cp "$pack_dir/manifest.json" "$work/meta/pack"
    read -r -a packed_tests < <("$python" -c 'import json, sys
print(" ".join(json.load(open(sys.argv[1]))["tests"]))' "$pack_dir/manifest.json")
    bin=$work/bin/bin/segsplat
    if [ $dry_run = 0 ]; then
      echo "== unpacking $pack_dir/binaries.tar.xz"
      mkdir -p "$work/bin"
      # Python's tarfile reads xz itself: the GPU image may have no xz program. The "data"
      # filter (where this Python has it) keeps the archive from writing outside the folder.
      "$python" -c 'import sys, tarfile
safe = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}
tarfile.open(sys.argv[1], "r:xz").extractall(sys.argv[2], **safe)' \
        "$pack_dir/binaries.tar.xz" "$work/bin" ||
        { pack_note="could not unpack $pack_dir/binaries.tar.xz"; bin=""; }
    fi
  elif [ -n "${SEGSPLAT_BIN:-}" ]; then
    bin=$(absolute "$SEGSPLAT_BIN")
    pack_note="no pack at $pack_dir: the CLI is SEGSPLAT_BIN=$bin, and there are no test binaries"
  elif [ $dry_run = 1 ]; then
    bin=$work/bin/bin/segsplat packed_tests=("${gpu_tests[@]}")
    pack_note="no pack at $pack_dir (dry run: the plan names what a pack holds)"
  else
    pack_note="no pack at $pack_dir and no SEGSPLAT_BIN: run 'bash scripts/gpu_check.sh pack' where cargo is"
  fi
  [ -z "$pack_note" ] || { echo "$pack_note" >&2; meta pack_note "$pack_note"; }
  if [ -n "$only_tests" ]; then
    local wanted=() name
    IFS=, read -r -a wanted <<<"$only_tests"
    for name in "${wanted[@]}"; do
      [[ " ${packed_tests[*]} " == *" $name "* ]] || die "--tests: '$name' is not in the pack (${packed_tests[*]})"
    done
    packed_tests=("${wanted[@]}")
  fi

  vulkan_loader "$dry_run"
  export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}

  if [ -n "$bin" ]; then
    step adapters adapters 60 "$bin" adapters
    # NVIDIA's hosts keep the driver's Vulkan manifest outside the loader's search path
    # (device README): point the loader at it and ask again when only software showed.
    local icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    local egl=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    if [ $dry_run = 0 ] && [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$icd" ] && ! has_hardware_adapter; then
      export VK_DRIVER_FILES=$icd
      [ ! -f "$egl" ] || export __EGL_VENDOR_LIBRARY_FILENAMES=$egl
      meta vk_driver_files "$icd"
      step adapters adapters-with-nvidia-icd 60 "$bin" adapters
    fi
  else
    skip adapters adapters "$pack_note" problem
  fi

  for name in "${packed_tests[@]}"; do
    if [ $skip_tests = 1 ]; then skip test "$name" "--skip-tests"
    elif [ -z "$bin" ]; then skip test "$name" "$pack_note" problem
    else
      step test "$name" "$test_timeout" env -u SEGSPLAT_SKIP_GPU_TESTS SEGSPLAT_BIN="$bin" \
        "$tests_dir/$name"
      # A binary whose tests failed runs once more with one test at a time: a failure that goes
      # away then is a race between tests sharing the adapter's context, one that stays is the
      # kernel's own (stop 54's deform_gpu on the H200 could not be told apart). One that timed
      # out runs again with only the tests that had not finished, one at a time, so that the
      # output names the test it was cut in (stop 54's raster_gpu stopped with 7 of 11 left, all
      # sharing one queue: one hang holds every test behind it, and which one was not known).
      local tests_rc unfinished
      tests_rc=$(cat "$step_dir/rc" 2>/dev/null || true)
      case $tests_rc in
        "" | 0) ;;
        124 | 137)
          unfinished=$(unfinished_tests "$tests_dir/$name" "$step_dir")
          # shellcheck disable=SC2086 # one word per test name
          step test-serial "$name" "$test_timeout" env -u SEGSPLAT_SKIP_GPU_TESTS \
            SEGSPLAT_BIN="$bin" "$tests_dir/$name" --test-threads=1 \
            ${unfinished:+--exact $unfinished} ;;
        *) step test-serial "$name" "$test_timeout" env -u SEGSPLAT_SKIP_GPU_TESTS \
          SEGSPLAT_BIN="$bin" "$tests_dir/$name" --test-threads=1 ;;
      esac
    fi
  done

  # The dataset: the caller's, the shared figurine beside or inside the checkout, the pack's
  # copy, else a synthetic scene.
  local source=argument
  if [ -z "$dataset" ]; then
    local candidate
    for candidate in "$repo/../shared/data/figurine" "$repo/shared/data/figurine" \
      "$pack_dir"/data/*; do
      if [ -d "$candidate" ]; then
        dataset=$(cd "$candidate" && pwd) source=$(basename "$candidate")
        break
      fi
    done
  fi
  if [ -z "$dataset" ]; then
    dataset=$work/synthetic-scene source=synthetic
    if [ -n "$bin" ] && [ $dry_run = 0 ]; then
      "$bin" synthetic-scene "$dataset" >/dev/null 2>"$work/synthetic.log" ||
        meta dataset_error "$(tail -3 "$work/synthetic.log")"
    fi
  fi
  meta dataset "$dataset"
  meta dataset_source "$source"

  bench plain-1000px 2000 240 --max-resolution 1000 --seed 42
  bench plain-256px 500 90 --max-resolution 256 --seed 42
  bench random-200k-profile 30 120 --max-resolution 1000 --init-random 200000 --no-densify \
    --profile-kernels 5 --seed 42
  bench object-loss-1000px 300 180 --max-resolution 1000 --object-loss --objects-per-level 1 \
    --seed 42
  # Kernels timed too: the H200's dynamic step was 43x a static one (stop 54), and the profile
  # names each GEMM product (forward, input and weight gradient) apart.
  bench deformation-256px 300 180 --max-resolution 256 --deformation --seed 42 \
    --profile-kernels 3 --busy-steps 20

  if [ $skip_job = 1 ]; then skip job job "--skip-job"
  elif [ -z "$bin" ]; then skip job job "$pack_note" problem
  else job "$job_steps"
  fi

  meta finished true
  if [ "$failures" -gt 0 ]; then exit 1; fi
}

meta() { printf '%s\n' "$2" >"$work/meta/$1"; }

# Written after every step, so a run cut short still leaves its report; a dry run writes it once.
write_report() {
  [ "$dry_run" = 0 ] || [ "${1:-}" = --summary ] || return 0
  "$python" "$repo/scripts/gpu_check_report.py" --work "$work" --out "$report" "$@"
}

# The loader the binaries open (wgpu loads libvulkan.so.1 at run time).
vulkan_loader() {
  local dry_run=$1
  if [ "$dry_run" = 1 ]; then meta vulkan_loader "not checked (dry run)"
  elif ldconfig -p 2>/dev/null | grep -q libvulkan; then meta vulkan_loader system
  elif ! compgen -G "$pack_dir/debs/*.deb" >/dev/null; then
    meta vulkan_loader "missing: none on the system and no .debs in $pack_dir/debs"
  elif [ "$(id -u)" != 0 ]; then
    meta vulkan_loader "missing: none on the system, and only root can unpack the .debs into /"
  else
    local deb
    # Into / as the device README does: the loader finds the driver's manifest only there.
    for deb in "$pack_dir"/debs/*.deb; do dpkg -x "$deb" /; done
    ldconfig
    meta vulkan_loader "unpacked from $(cd "$pack_dir/debs" && echo *.deb)"
  fi
  echo "Vulkan loader: $(cat "$work/meta/vulkan_loader")"
}

has_hardware_adapter() {
  local last
  last=$(find "$work/steps" -maxdepth 1 -name '*-adapters*' | sort | tail -1)
  "$python" -c 'import json, sys
sys.exit(0 if any(not a.get("is_software") for a in json.load(open(sys.argv[1]))) else 1)' \
    "$last/stdout" 2>/dev/null
}

new_step() {
  step_index=$((step_index + 1))
  step_dir=$work/steps/$(printf '%02d' "$step_index")-$2
  mkdir -p "$step_dir"
  echo "$1" >"$step_dir/kind"
  echo "$2" >"$step_dir/name"
}

# skip KIND NAME REASON [problem]: records a step not run; a problem (no binaries) fails the run,
# an option that asked for the skip does not.
skip() {
  new_step "$1" "$2"
  echo "$3" >"$step_dir/skipped"
  echo "[$1 $2] skipped: $3"
  [ "${4:-}" != problem ] || failures=$((failures + 1))
  write_report
}

# unfinished_tests BINARY STEP_DIR: the tests BINARY lists (libtest's `--list`, which touches no
# adapter) that the step's output gives no result for, one per line in the list's order; also
# kept as the step's `unfinished` for the report.
unfinished_tests() {
  local listed
  listed=$(timeout 30 "$1" --list --format terse 2>/dev/null | sed -n 's/: test$//p' || true)
  sed -n 's/^test \(.*\) \.\.\. \(ok\|FAILED\|ignored\).*$/\1/p' "$2/stdout" >"$2/finished"
  { grep -vxF -f "$2/finished" <<<"$listed" || true; } | tee "$2/unfinished"
}

# step KIND NAME TIMEOUT COMMAND...: runs COMMAND with its output in the step's folder, its
# timeout scaled and cut to what is left of the budget.
step() {
  local kind=$1 name=$2 limit=$3
  shift 3
  new_step "$kind" "$name"
  printf '%q ' "$@" >"$step_dir/command"
  limit=$(awk -v t="$limit" -v f="$timeout_scale" 'BEGIN { printf "%d", t * f + 0.5 }')
  local left=$((budget - ($(now) - start) - reserve))
  if [ "$left" -lt 20 ]; then
    echo "the budget of $budget s was spent" >"$step_dir/skipped"
    echo "[$kind $name] skipped: budget spent"
    failures=$((failures + 1))
    write_report
    return 0
  fi
  [ "$limit" -le "$left" ] || limit=$left
  echo "$limit" >"$step_dir/timeout"
  if [ "$dry_run" = 1 ]; then
    echo "dry run" >"$step_dir/skipped"
    echo "[$kind $name] would run, timeout ${limit}s: $*"
    write_report
    return 0
  fi
  echo "[$kind $name] timeout ${limit}s: $*"
  local began rc=0
  began=$(date +%s.%N)
  timeout -k 15 "$limit" "$@" >"$step_dir/stdout" 2>"$step_dir/stderr" </dev/null || rc=$?
  echo "$rc" >"$step_dir/rc"
  awk -v a="$began" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f\n", b - a }' >"$step_dir/seconds"
  [ "$rc" = 0 ] || failures=$((failures + 1))
  echo "[$kind $name] exit $rc after $(cat "$step_dir/seconds") s"
  write_report
}

# bench NAME STEPS TIMEOUT FLAGS...: `segsplat bench` on the dataset with STEPS scaled.
bench() {
  local name=$1 steps=$2 limit=$3
  shift 3
  if [ "$skip_benches" = 1 ]; then skip bench "$name" "--skip-benches"; return 0; fi
  if [ -z "$bin" ]; then skip bench "$name" "$pack_note" problem; return 0; fi
  steps=$(awk -v s="$steps" -v f="$scale" 'BEGIN { n = int(s * f + 0.5); print (n < 5 ? 5 : n) }')
  step bench "$name" "$limit" "$bin" bench "$dataset" --steps "$steps" "$@" --json
}

# The whole job as a user runs it: scripts/demo.sh with the packed binary.
job() {
  local steps=$1 demo=${SEGSPLAT_GPU_CHECK_DEMO:-$repo/scripts/demo.sh} port
  port=$("$python" -c 'import socket
s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  # demo.sh waits for the server with curl, which a bare GPU image may lack.
  local run_env=(env)
  if ! command -v curl >/dev/null; then
    mkdir -p "$work/shims"
    run_env+=(PATH="$work/shims:$PATH")
    cat >"$work/shims/curl" <<'EOF'
#!/bin/sh
# Stands in for `curl -sf URL` (demo.sh's health check) where curl is missing.
for url; do :; done
exec python3 -c 'import sys, urllib.request
urllib.request.urlopen(sys.argv[1], timeout=5).read()' "$url" 2>/dev/null
EOF
    chmod +x "$work/shims/curl"
  fi
  step job job 3600 "${run_env[@]}" SEGSPLAT_BIN="$bin" \
    SEGSPLAT_DEMO_OUT="$work/demo" SEGSPLAT_DEMO_PORT="$port" bash "$demo" "$dataset" "$steps"
  echo "$work/demo" >"$step_dir/demo_out"
  echo "$steps" >"$step_dir/job_steps"
  write_report
}

case ${1:-} in
  pack) shift; pack "$@" ;;
  run) shift; run "$@" ;;
  -h | --help | help) usage ;;
  "") usage >&2; exit 2 ;;
  *) die "unknown mode '$1': pack or run (see --help)" ;;
esac
