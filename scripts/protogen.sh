#!/usr/bin/env bash
# Regenerates the gRPC code of segsplat-api (crates/api/src/generated/) from crates/api/proto,
# with tools/protogen (its own workspace: the service's build never compiles protox). Run it
# after changing a .proto and commit what it writes; until then the api's unit test
# `generated_grpc_code_is_from_the_proto_in_the_tree` fails.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo run --locked --quiet --manifest-path tools/protogen/Cargo.toml --target-dir target/protogen
