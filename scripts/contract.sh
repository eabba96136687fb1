#!/usr/bin/env bash
# The REST contract against a live server (docs/service.md, "The contract"): starts
# `segsplat serve` on 127.0.0.1 with a temporary data dir and a bearer token, fetches the OpenAPI
# document it serves, validates it with openapi-spec-validator (OpenAPI 3.1), then runs
# schemathesis against the server for a bounded time; any failure fails the script.
#
# Usage: bash scripts/contract.sh [MAX_EXAMPLES]   (default 30 generated cases per operation)
# Both tools come from PyPI (scripts/bootstrap.sh pins them). Without them the script says so
# and skips, except under CI=true, where a missing tool fails.
set -euo pipefail
cd "$(dirname "$0")/.."

max_examples=${1:-${SEGSPLAT_CONTRACT_EXAMPLES:-30}}
# The whole schemathesis run stops after this many seconds, whatever is left.
max_seconds=${SEGSPLAT_CONTRACT_SECONDS:-120}

for tool in openapi-spec-validator schemathesis curl; do
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
binary=target/debug/segsplat

LIVE_TOKEN_PREFIX=contract source scripts/live_server.sh

# API only (workers.enabled=false): schemathesis may queue jobs, which then stay queued instead
# of training on this machine's CPU. An admin token (so `GET /v1/workers` is reachable too), so
# the document declares bearer auth and schemathesis checks that routes refuse requests without.
# A 4 MiB upload limit keeps what generated uploads can write to the temporary dir small.
live_server_start contract "$binary" \
  SEGSPLAT_AUTH__TOKEN="[{token = \"$token\", admin = true}]" \
  SEGSPLAT_WORKERS__ENABLED=false \
  SEGSPLAT_LIMITS__MAX_UPLOAD_BYTES=$((4 << 20))
curl -fsS "$base/v1/openapi.json" -o "$work/openapi.json"

echo "== openapi-spec-validator"
openapi-spec-validator "$work/openapi.json"

echo "== schemathesis (at most $max_examples cases per operation, ${max_seconds}s)"
# Every check and every phase; scripts/schemathesis.toml says where and why two operations
# accept more statuses for schema-valid requests. No scene is uploaded first: schemathesis could
# not learn its id (uploads it generates are never valid archives), so the operations on one
# answer 404 here; tests/service_*.rs cover them on real scenes.
# A fixed seed (SEGSPLAT_CONTRACT_SEED to vary it): a red run is reproducible, not luck. Run
# from the temporary folder, where schemathesis keeps its cache (.schemathesis/).
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
  --workers 2) || status=$?

if [ "$status" -ne 0 ]; then
  echo "contract: schemathesis found failures (server log follows)" >&2
  tail -n 50 "$work/server.log" >&2
  exit "$status"
fi
echo "contract: the document validates and schemathesis found no failures"
