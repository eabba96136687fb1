#!/usr/bin/env bash
# Every test of the workspace, as `cargo test --workspace --lib --bins --tests` runs them, but on
# two lanes: cargo runs one test binary at a time, and a binary whose last test is a long one
# (a dynamic scene's training, a job through the service) leaves a core idle until it ends. Here
# the binaries are jobs on a queue that `SEGSPLAT_TEST_LANES` cargo processes (default 2) take
# from, the longest first, so the short ones fill in beside them. Cargo releases its build lock
# before it runs a test, so the lanes do not wait on each other; the build is done before this
# runs (scripts/test.sh builds every target first), so no lane compiles.
#
# Each job's output is printed whole when it ends, never interleaved with another's, and the
# run fails, naming the failed jobs, if any job fails. Extra arguments go to every cargo
# invocation (e.g. `--release`).
set -euo pipefail
cd "$(dirname "$0")/.."
lanes=${SEGSPLAT_TEST_LANES:-2}

# The integration tests that take longest, longest first: each is a job of its own. Measured
# one binary at a time on the 2-core machine (CPU-seconds; README, "CI time"). A test missing
# from this list is still run, in one of the batches below.
long=(
  service_dynamic                # 148
  train_dynamic                  # 83
  service_training_jobs          # 62
  train_synthetic                # 44
  segment_then_splat_synthetic   # 32
  segment_then_splat_association # 32
  service_blob_outage            # 20, 31 s of wall time waiting on an outage
  gpu_loss                       # 16
  segment_propagation            # 14
  store_backends                 # 4, 11 s of wall time
  cluster_processes              # 8, 10 s of wall time
  mask_render_shedding           # 11
  service_masks                  # 11
)

jobs_file=$(mktemp)
work=$(mktemp -d)
trap 'rm -rf "$jobs_file" "$work"' EXIT
for name in "${long[@]}"; do
  [ -f "tests/$name.rs" ] || { echo "run_tests.sh lists tests/$name.rs, which is gone" >&2; exit 1; }
  echo "--test $name" >>"$jobs_file"
done
# Every other integration test, dealt round-robin into four batches (one cargo process each:
# a cargo invocation costs about half a second even when it builds nothing), and the unit tests
# of every crate and binary as one more job.
batches=(" " " " " " " ")
index=0
for path in tests/*.rs; do
  name=$(basename "$path" .rs)
  case " ${long[*]} " in *" $name "*) continue ;; esac
  batches[index % 4]+=" --test $name"
  index=$((index + 1))
done
for batch in "${batches[@]}"; do
  [ -n "${batch// /}" ] && echo "$batch" >>"$jobs_file"
done
echo "--lib --bins" >>"$jobs_file"

# One job: its cargo run into a log of its own, then the log printed under a lock.
run_job() {
  local work=$1 targets
  # shellcheck disable=SC2086 # one space between words
  targets=$(echo $2)
  shift 2
  local log
  log=$(mktemp -p "$work")
  local status=0
  # shellcheck disable=SC2086 # the targets are words
  cargo test --locked --workspace "$@" $targets >"$log" 2>&1 || status=$?
  {
    flock 9
    echo "== $(date +%H:%M:%S) cargo test $targets (exit $status)"
    cat "$log"
    [ "$status" -eq 0 ] || echo "$targets" >>"$work/failed"
  } 9>"$work/lock"
  rm -f "$log"
  return 0
}
export -f run_job

tr '\n' '\0' <"$jobs_file" | xargs -0 -P "$lanes" -I{} bash -c 'run_job "$0" "$1" "${@:2}"' "$work" {} "$@"
if [ -s "$work/failed" ]; then
  echo "failed test jobs:" >&2
  sed 's/^/  cargo test --workspace /' "$work/failed" >&2
  exit 1
fi
