#!/usr/bin/env bash
# Runs the cargo-fuzz targets in fuzz/ one at a time (docs/fuzzing.md).
#
#   scripts/fuzz.sh SECONDS [TARGET...]   each target (default: all) for SECONDS
#
# New interesting inputs go to fuzz/corpus-work/<target> (ignored by git); the committed seeds
# in fuzz/corpus/<target> are only read. Crashes, hangs (-timeout) and runaway memory
# (-rss_limit_mb, -malloc_limit_mb) stop a target and leave the input in
# fuzz/artifacts/<target>/; the script then goes on with the next target and exits non-zero.
# Needs nightly Rust and cargo-fuzz; without them it says so and exits 0 (stable CI replays the
# corpus in tests/fuzz_corpus.rs instead).
set -uo pipefail
cd "$(dirname "$0")/../fuzz"
seconds=${1:?usage: scripts/fuzz.sh SECONDS [TARGET...]}
shift
if ! cargo +nightly --version >/dev/null 2>&1; then
    echo "fuzz: skipped, no nightly toolchain (rustup toolchain install nightly); the corpus replay (tests/fuzz_corpus.rs) ran on stable"
    exit 0
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz: skipped, cargo-fuzz is not installed (cargo install --locked cargo-fuzz@0.13.2); the corpus replay (tests/fuzz_corpus.rs) ran on stable"
    exit 0
fi
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(ls fuzz_targets | sed 's/\.rs$//')
fi
# Parsers write their input to a temporary folder per run: a RAM disk keeps that cheap.
if [ -d /dev/shm ] && [ -w /dev/shm ]; then
    export TMPDIR=/dev/shm
fi
cargo +nightly fuzz build -O --debug-assertions || exit 1
failed=0
for target in "${targets[@]}"; do
    mkdir -p "corpus-work/$target" "artifacts/$target"
    echo "fuzz: $target for ${seconds}s"
    # -jobs=1 -workers=1: one fuzzing process on one core, its output in fuzz-0.log.
    rm -f fuzz-0.log
    cargo +nightly fuzz run -O --debug-assertions "$target" \
        "corpus-work/$target" "corpus/$target" -- \
        -max_total_time="$seconds" -jobs=1 -workers=1 -timeout=10 \
        -rss_limit_mb=2048 -malloc_limit_mb=1024 -print_final_stats=1 \
        -artifact_prefix="artifacts/$target/" >"artifacts/$target.run.log" 2>&1
    status=$?
    if [ -f fuzz-0.log ]; then mv fuzz-0.log "artifacts/$target.log"; fi
    grep -hE "^#[0-9]+[[:space:]]+(INITED|DONE)|^stat::|^==[0-9]+==|^SUMMARY|Test unit written|^Done" \
        "artifacts/$target.log" "artifacts/$target.run.log" 2>/dev/null | tail -n 12
    if [ "$status" -ne 0 ]; then
        echo "fuzz: $target FAILED (exit $status); input and log under fuzz/artifacts/$target"
        failed=1
    fi
done
exit $failed
