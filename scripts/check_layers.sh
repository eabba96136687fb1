#!/usr/bin/env bash
# The workspace's dependency graph is its architecture (docs/architecture.md); this fails when a
# crate reaches up or sideways, or when an engine-side crate pulls in a service framework.
#   - each crate may depend only on crates listed before it in LAYERS;
#   - the crates up to `eval` must not depend, even transitively, on tokio, axum, tonic or sqlx.
set -euo pipefail
cd "$(dirname "$0")/.."
LAYERS=(gpu scene engine vision method eval service api)
ENGINE_SIDE=(gpu scene engine vision method eval)
FRAMEWORKS='^(tokio|axum|tonic|sqlx|hyper|tower) v'
status=0
for index in "${!LAYERS[@]}"; do
    crate=segsplat-${LAYERS[$index]}
    allowed=" ${LAYERS[*]:0:$index} "
    direct=$(cargo tree --locked -p "$crate" -e normal --depth 1 --prefix none |
        awk 'NR > 1 && $1 ~ /^segsplat-/ { sub(/^segsplat-/, "", $1); print $1 }' | sort -u)
    for dependency in $direct; do
        if [[ $allowed != *" $dependency "* ]]; then
            echo "layering: $crate depends on segsplat-$dependency, which is not below it"
            status=1
        fi
    done
done
for layer in "${ENGINE_SIDE[@]}"; do
    crate=segsplat-$layer
    frameworks=$(cargo tree --locked -p "$crate" -e normal --prefix none | grep -E "$FRAMEWORKS" | sort -u || true)
    if [[ -n $frameworks ]]; then
        echo "layering: $crate depends on a service framework:"
        echo "$frameworks" | sed 's/^/    /'
        status=1
    fi
done
if [[ $status == 0 ]]; then
    echo "layering: ${LAYERS[*]} (each uses only those before it; none up to eval uses tokio, axum, tonic or sqlx)"
fi
exit $status
