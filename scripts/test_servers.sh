#!/usr/bin/env bash
# Sourced by scripts/test.sh: starts the real servers the storage tests run against, on
# 127.0.0.1, and exports where they are. Today: an S3-compatible server (s3rver, installed from
# the npm registry by scripts/bootstrap.sh) with one bucket. Tests whose server is absent skip
# with the reason, except in CI (CI=true), where this script fails instead.
# Stopped when the sourcing shell exits.

SEGSPLAT_TOOLS_DIR=${SEGSPLAT_TOOLS_DIR:-$HOME/.cache/segsplat-tools}
s3rver_bin="$SEGSPLAT_TOOLS_DIR/s3rver/node_modules/.bin/s3rver"

start_s3rver() {
    if [ ! -x "$s3rver_bin" ] || ! command -v node >/dev/null 2>&1; then
        if [ "${CI:-}" = "true" ]; then
            echo "error: CI needs s3rver at $s3rver_bin (scripts/bootstrap.sh installs it)" >&2
            return 1
        fi
        echo "note: no S3-compatible test server ($s3rver_bin); the object-store tests will skip"
        return 0
    fi
    local port data
    port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
    data=$(mktemp -d)
    "$s3rver_bin" --directory "$data" --address 127.0.0.1 --port "$port" \
        --configure-bucket segsplat-test --silent >"$data.log" 2>&1 &
    SEGSPLAT_TEST_S3_PID=$!
    SEGSPLAT_TEST_S3_DATA=$data
    for _ in $(seq 1 100); do
        if curl -sf "http://127.0.0.1:$port/" >/dev/null 2>&1; then
            export SEGSPLAT_TEST_S3_ENDPOINT="http://127.0.0.1:$port"
            export SEGSPLAT_TEST_S3_BUCKET=segsplat-test
            echo "s3rver on $SEGSPLAT_TEST_S3_ENDPOINT (bucket segsplat-test, data $data)"
            return 0
        fi
        sleep 0.1
    done
    echo "error: s3rver did not start; its log:" >&2
    cat "$data.log" >&2
    return 1
}

stop_test_servers() {
    if [ -n "${SEGSPLAT_TEST_S3_PID:-}" ]; then
        kill "$SEGSPLAT_TEST_S3_PID" 2>/dev/null || true
        rm -rf "$SEGSPLAT_TEST_S3_DATA" "$SEGSPLAT_TEST_S3_DATA.log"
    fi
}

trap stop_test_servers EXIT
start_s3rver
