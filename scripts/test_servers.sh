#!/usr/bin/env bash
# Sourced by scripts/test.sh: starts the real servers the storage tests run against, on
# 127.0.0.1, and exports where they are. Today: an S3-compatible server (s3rver, installed from
# the npm registry by scripts/bootstrap.sh) with one bucket, and PostgreSQL (Debian's package) in
# a throwaway cluster. Tests whose server is absent skip with the reason, except in CI (CI=true),
# where this script fails instead.
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

# A throwaway PostgreSQL cluster with trust authentication on 127.0.0.1 only. Every test's
# fresh database is written to the WAL too; a small max_wal_size recycles it (the default 1 GB
# let the cluster reach 543 MB in a CI run, most of it WAL). PostgreSQL refuses
# to run as root, so as root the cluster belongs to the `postgres` user the package created.
start_postgres() {
    local bin
    bin=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1)
    if [ -z "$bin" ] || [ ! -x "$bin/initdb" ]; then
        if [ "${CI:-}" = "true" ]; then
            echo "error: CI needs PostgreSQL (Debian's postgresql package; scripts/bootstrap.sh installs it)" >&2
            return 1
        fi
        echo "note: no PostgreSQL server binaries; the Postgres store tests will skip"
        return 0
    fi
    local as_user=() port data
    data=$(mktemp -d)
    if [ "$(id -u)" -eq 0 ]; then
        chown postgres "$data"
        as_user=(runuser -u postgres --)
    fi
    port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
    if ! "${as_user[@]}" "$bin/initdb" -D "$data/cluster" -A trust -U segsplat >"$data.log" 2>&1 \
        || ! "${as_user[@]}" "$bin/pg_ctl" -D "$data/cluster" -l "$data/server.log" -w \
            -o "-c listen_addresses=127.0.0.1 -p $port -k $data -c max_connections=300 -c fsync=off -c max_wal_size=96MB -c min_wal_size=32MB" \
            start >>"$data.log" 2>&1; then
        echo "error: PostgreSQL did not start; its log:" >&2
        cat "$data.log" "$data/server.log" >&2 2>/dev/null
        return 1
    fi
    SEGSPLAT_TEST_PG_DATA=$data
    SEGSPLAT_TEST_PG_BIN=$bin
    SEGSPLAT_TEST_PG_AS=("${as_user[@]}")
    export SEGSPLAT_TEST_POSTGRES_URL="postgres://segsplat@127.0.0.1:$port/postgres"
    echo "PostgreSQL on $SEGSPLAT_TEST_POSTGRES_URL (data $data)"
}

stop_test_servers() {
    if [ -n "${SEGSPLAT_TEST_PG_DATA:-}" ]; then
        "${SEGSPLAT_TEST_PG_AS[@]}" "$SEGSPLAT_TEST_PG_BIN/pg_ctl" -D "$SEGSPLAT_TEST_PG_DATA/cluster" \
            -m immediate stop >/dev/null 2>&1 || true
        rm -rf "$SEGSPLAT_TEST_PG_DATA" "$SEGSPLAT_TEST_PG_DATA.log"
    fi
    if [ -n "${SEGSPLAT_TEST_S3_PID:-}" ]; then
        kill "$SEGSPLAT_TEST_S3_PID" 2>/dev/null || true
        rm -rf "$SEGSPLAT_TEST_S3_DATA" "$SEGSPLAT_TEST_S3_DATA.log"
    fi
}

trap stop_test_servers EXIT
start_s3rver
start_postgres
