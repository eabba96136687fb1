#!/usr/bin/env bash
# The REST contract against a live server (docs/service.md, "The contract"): starts
# `segsplat serve` on 127.0.0.1 with a temporary data dir and a bearer token, trains a small
# synthetic scene there (a short segment_then_splat job with the tiny test models), downloads its
# trained files through a client openapi-python-client generates from the served document,
# restarts the server without workers on the same data, fetches the OpenAPI document, validates it
# with openapi-spec-validator (OpenAPI 3.1), then runs schemathesis against the server for a
# bounded time, with the operations on a scene or a job pointed at the trained scene and a
# finished job (scripts/schemathesis.toml); any failure fails the script.
#
# Usage: bash scripts/contract.sh [MAX_EXAMPLES]   (default 30 generated cases per operation)
# The tools come from PyPI (scripts/bootstrap.sh pins them). Without them the script says so
# and skips, except under CI=true, where a missing tool fails.
set -euo pipefail
cd "$(dirname "$0")/.."

max_examples=${1:-${SEGSPLAT_CONTRACT_EXAMPLES:-30}}
# The whole schemathesis run stops after this many seconds, whatever is left.
max_seconds=${SEGSPLAT_CONTRACT_SECONDS:-120}

for tool in openapi-spec-validator schemathesis openapi-python-client curl; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    if [ "${CI:-}" = "true" ]; then
      echo "contract: $tool is missing (scripts/bootstrap.sh installs it)" >&2
      exit 1
    fi
    echo "skipping the contract checks: $tool is not installed (scripts/bootstrap.sh installs it)"
    exit 0
  fi
done

# The binary as the tests build it (the same features, so after scripts/test.sh's test phase
# nothing is rebuilt).
cargo test --locked --workspace --no-run --test openapi_contract
binary=${CARGO_TARGET_DIR:-target}/debug/segsplat

LIVE_TOKEN_PREFIX=contract source scripts/live_server.sh

api() { curl -fsS -H "Authorization: Bearer $token" "$@"; }
field() { python3 -c 'import json, sys; print(json.load(sys.stdin)[sys.argv[1]])' "$1"; }
models="$PWD/tests/fixtures/models/tiny"

# A trained scene first, so the operations on one answer more than 404 (before issue 41 no scene
# existed and schemathesis never saw a mask, a download or an event stream): three coloured
# spheres with masks, trained for a few steps on this machine's adapter with workers on.
"$binary" synthetic-scene "$work/scene" --frames 9 --width 96 --height 72 >/dev/null
(cd "$work/scene" && python3 -m zipfile -c "$work/scene.zip" .)
live_server_start "contract (training)" "$binary" \
  SEGSPLAT_AUTH__TOKEN="[{token = \"$token\", admin = true}]" \
  SEGSPLAT_MODELS__DIR="$models"
scene=$(api -X POST -H "Content-Type: application/zip" --data-binary @"$work/scene.zip" \
  "$base/v1/scenes?name=contract" | field id)
job=$(api -X POST -H "Content-Type: application/json" \
  -d '{"kind": "segment_then_splat", "config": {"steps": 30, "masks": "user", "checkpoint_every": 0}}' \
  "$base/v1/scenes/$scene/jobs" | field id)
echo "== training scene $scene (job $job)"
state=queued
for _ in $(seq 1 600); do
  state=$(api "$base/v1/jobs/$job" | field state)
  [ "$state" = queued ] || [ "$state" = running ] || break
  sleep 1
done
if [ "$state" != succeeded ]; then
  echo "contract: the training job ended $state (server log follows)" >&2
  api "$base/v1/jobs/$job" >&2 || true
  tail -n 50 "$work/server.log" >&2
  exit 1
fi

# A client generated from the served document downloads every trained file as what it is: the
# JSON files parsed, the binary ones as bytes (scripts/trained_files_client.py; issue 41).
echo "== generated client (openapi-python-client)"
curl -fsS "$base/v1/openapi.json" -o "$work/openapi-trained.json"
mkdir -p "$work/client"
openapi-python-client generate --path "$work/openapi-trained.json" \
  --output-path "$work/client/segsplat_client" --meta none >"$work/client.log" 2>&1 || {
  echo "contract: openapi-python-client could not generate a client" >&2
  cat "$work/client.log" >&2
  exit 1
}
python3 scripts/trained_files_client.py "$work/client" "$base" "$token" "$scene"
live_server_stop

# API only (workers.enabled=false), on the same data: schemathesis queues jobs, which then stay
# queued instead of training on this machine's CPU. An admin token (so `GET /v1/workers` is
# reachable too), so the document declares bearer auth and schemathesis checks that routes
# refuse requests without. A 4 MiB upload limit keeps what generated uploads can write to the
# temporary dir small; masks of at most 256 pixels a side keep generated renders quick.
live_server_start contract "$binary" \
  SEGSPLAT_AUTH__TOKEN="[{token = \"$token\", admin = true}]" \
  SEGSPLAT_WORKERS__ENABLED=false \
  SEGSPLAT_MODELS__DIR="$models" \
  SEGSPLAT_QUERY__MAX_MASK_SIDE=256 \
  SEGSPLAT_LIMITS__MAX_UPLOAD_BYTES=$((4 << 20))
# A job that stays queued keeps the scene from being deleted (409) during the run; a cancelled
# one is what the job operations get: its event stream ends after its history.
new_job() {
  api -X POST -H "Content-Type: application/json" -d '{"kind": "reconstruct"}' \
    "$base/v1/scenes/$scene/jobs" | field id
}
new_job >/dev/null
finished=$(new_job)
api -X POST "$base/v1/jobs/$finished/cancel" >/dev/null
export SEGSPLAT_CONTRACT_SCENE=$scene SEGSPLAT_CONTRACT_JOB=$finished
curl -fsS "$base/v1/openapi.json" -o "$work/openapi.json"

echo "== openapi-spec-validator"
openapi-spec-validator "$work/openapi.json"

echo "== schemathesis (at most $max_examples cases per operation, ${max_seconds}s)"
# Every check and every phase; scripts/schemathesis.toml pins the scene and job ids and says
# where and why some operations accept more statuses for schema-valid requests.
# A fixed seed (SEGSPLAT_CONTRACT_SEED to vary it): a red run is reproducible, not luck. Run
# from the temporary folder, where schemathesis keeps its cache (.schemathesis/).
# One worker: with two (threads), a busy CI run once failed on schemathesis's own
# "SystemError: AST constructor recursion depth mismatch" (hypothesis describing a lambda with
# ast.parse in both threads at once; Python 3.11's ast recursion count is not per thread), not
# on anything the server answered. The contract runs beside the tests, which take longer.
repo=$PWD
status=0
(cd "$work" && schemathesis --config-file "$repo/scripts/schemathesis.toml" run openapi.json \
  --url "$base" \
  --header "Authorization: Bearer $token" \
  --checks all \
  --max-examples "$max_examples" \
  --max-time "$max_seconds" \
  --request-timeout 10 \
  --seed "${SEGSPLAT_CONTRACT_SEED:-1}" \
  --workers 1) || status=$?

if [ "$status" -ne 0 ]; then
  echo "contract: schemathesis found failures (server log follows)" >&2
  tail -n 50 "$work/server.log" >&2
  exit "$status"
fi
echo "contract: the document validates and schemathesis found no failures"
