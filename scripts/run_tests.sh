#!/usr/bin/env bash
# Every test of the workspace, as `cargo test --workspace --lib --bins --tests` runs them, but on
# two lanes: cargo runs one test binary at a time, and a binary whose last test is a long one
# (a dynamic scene's training, a job through the service) leaves a core idle until it ends. Here
# the binaries are jobs on a queue that `SEGSPLAT_TEST_LANES` cargo processes (default 2) take
# from, the longest first, so the short ones fill in beside them. Cargo releases its build lock
# before it runs a test, so the lanes do not wait on each other; the build is done before this
# runs (scripts/test.sh builds every target first), so no lane compiles.
#
# Each job's output is printed whole when it ends, never interleaved with another's (the queue
# is scripts/lanes.sh), and the run fails, naming the failed jobs, if any job fails. Extra
# arguments go to every cargo invocation (e.g. `--release`).
set -euo pipefail
cd "$(dirname "$0")/.."
lanes=${SEGSPLAT_TEST_LANES:-2}

# The integration tests that take longest, longest first: each is a job of its own. Measured
# one binary at a time on the 2-core machine (CPU-seconds; README, "CI time"). A test missing
# from this list is still run, in one of the batches below.
long=(
  service_dynamic                # 127 (stop 63, this machine: 85 s)
  train_dynamic                  # 92 (stop 63, this machine: 66 s)
  service_training_jobs          # 62
  train_synthetic                # 44
  segment_then_splat_synthetic   # 32
  segment_then_splat_association # 32
  commands                       # 32, 22 s of wall time (the demo script)
  models                         # 24
  service_blob_outage            # 20, 31 s of wall time waiting on an outage
  gpu_loss                       # 16
  segment                        # 15
  store_backends                 # 4, 11 s of wall time
  cluster_processes              # 8, 10 s of wall time
  mask_render_shedding           # 11
  service_masks                  # 11
)

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
source scripts/lanes.sh
for name in "${long[@]}"; do
  [ -f "tests/$name.rs" ] || [ -f "tests/$name/main.rs" ] ||
    { echo "run_tests.sh lists the test $name, which is gone" >&2; exit 1; }
  lane_job "$name" cargo test --locked --workspace "$@" --test "$name"
done
# Every other integration test (a file `tests/NAME.rs` or a folder `tests/NAME/main.rs`, as
# cargo finds them), dealt round-robin into four batches (one cargo process each: a cargo
# invocation costs about half a second even when it builds nothing), and the unit tests of
# every crate and binary as one more job.
batches=("" "" "" "")
index=0
for path in tests/*.rs tests/*/main.rs; do
  [ -e "$path" ] || continue # a pattern that matched nothing
  name=${path#tests/}
  name=${name%/main.rs}
  name=${name%.rs}
  case " ${long[*]} " in *" $name "*) continue ;; esac
  batches[index % 4]+=" --test $name"
  index=$((index + 1))
done
for index in "${!batches[@]}"; do
  # shellcheck disable=SC2086 # the batch is words
  [ -z "${batches[index]}" ] ||
    lane_job "batch-$((index + 1))" cargo test --locked --workspace "$@" ${batches[index]}
done
lane_job unit cargo test --locked --workspace "$@" --lib --bins

if ! lanes_run "$lanes" "$work" log; then
  echo "failed test jobs (their commands are above):" $(cat "$work/failed") >&2
  exit 1
fi
