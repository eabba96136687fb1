#!/usr/bin/env bash
# Sourced by the scripts that test a live `segsplat serve` on 127.0.0.1 (contract.sh,
# console_e2e.sh). Gives them:
#   work              a temporary folder, removed on exit with the server stopped;
#   token             a fresh random bearer token (prefix from LIVE_TOKEN_PREFIX);
#   base              the server's REST URL, once live_server_start has run;
#   live_server_start NAME BINARY [VAR=VALUE ...]
#                     starts BINARY serve with its data dir in $work, free ports, the
#                     variables given, and logs in $work/server.log; waits for /healthz, or
#                     prints the log and exits 1 naming NAME.
#   live_server_stop  stops that server (SIGTERM, waits); its data dir stays, so a server started
#                     after it sees the same scenes and jobs.

work=$(mktemp -d)
server_pid=""
live_server_stop() {
  if [ -n "$server_pid" ]; then
    kill "$server_pid" 2>/dev/null || true
    wait "$server_pid" 2>/dev/null || true
    server_pid=""
  fi
}
live_server_cleanup() {
  live_server_stop
  rm -rf "$work"
}
trap live_server_cleanup EXIT

free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}
token="${LIVE_TOKEN_PREFIX:-test}-$(python3 -c 'import secrets; print(secrets.token_hex(8))')"

live_server_start() {
  local name=$1 binary=$2
  shift 2
  local http_port grpc_port
  http_port=$(free_port)
  grpc_port=$(free_port)
  base="http://127.0.0.1:$http_port"
  env SEGSPLAT_DATA_DIR="$work/data" \
    SEGSPLAT_HTTP_ADDR="127.0.0.1:$http_port" \
    SEGSPLAT_GRPC_ADDR="127.0.0.1:$grpc_port" \
    SEGSPLAT_LOG__LEVEL=warn \
    "$@" "$binary" serve >>"$work/server.log" 2>&1 &
  server_pid=$!
  for _ in $(seq 1 240); do
    curl -fsS "$base/healthz" >/dev/null 2>&1 && return 0
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.5
  done
  echo "$name: segsplat serve did not come up on $base; its log:" >&2
  cat "$work/server.log" >&2
  exit 1
}
