#!/usr/bin/env bash
# The main job on the embedded defaults, as a user runs it: start `segsplat serve` (SQLite and a
# local blob dir under ./data, the best GPU or the software Vulkan adapter), upload a dataset,
# run Segment then Splat on it (`segment_then_splat`: masks from the dataset, else SAM when a
# model dir is configured, else the classical segmenter) while printing progress, then list the
# objects it found, render one object's mask for frame 0 and show where the results are.
#
#   bash scripts/demo.sh [DATASET_DIR] [STEPS]
#
# Without DATASET_DIR it uses ../shared/data/figurine when present, else a synthetic scene.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
cargo build --release --locked
bin=target/release/segsplat
http=127.0.0.1:${SEGSPLAT_DEMO_PORT:-8080}
dataset=${1:-}
steps=${2:-500}
work=$(mktemp -d)
trap 'kill "${server:-}" 2>/dev/null || true; rm -rf "$work"' EXIT

if [ -z "$dataset" ]; then
  if [ -d ../shared/data/figurine ]; then dataset=../shared/data/figurine
  else dataset=$work/synthetic; "$bin" synthetic-scene "$dataset"; fi
fi

"$bin" serve --data-dir ./data --http "$http" --grpc 127.0.0.1:0 &
server=$!
for _ in $(seq 100); do curl -sf "http://$http/healthz" >/dev/null && break; sleep 0.2; done

tar czf "$work/scene.tar.gz" -C "$dataset" .
json() { python3 -c "import json,sys; print(json.load(sys.stdin)$1)"; }
scene=$(curl -sf -H 'content-type: application/gzip' --data-binary @"$work/scene.tar.gz" \
  "http://$http/v1/scenes" | json "['id']")
echo "scene $scene uploaded"
job=$(curl -sf -H 'content-type: application/json' \
  -d "{\"kind\":\"segment_then_splat\",\"config\":{\"steps\":$steps,\"max_resolution\":256,\"checkpoint_every\":0}}" \
  "http://$http/v1/scenes/$scene/jobs" | json "['id']")
echo "job $job queued; progress:"
while :; do
  state=$(curl -sf "http://$http/v1/jobs/$job")
  echo "$state" | python3 -c "import json,sys; j=json.load(sys.stdin); p=j.get('progress') or {}; print(' ', j['state'], p.get('stage',''), p.get('step',''), '/', p.get('total_steps',''), {k: round(v,4) for k,v in (p.get('metrics') or {}).items()})"
  case $(echo "$state" | json "['state']") in succeeded|failed|cancelled) break;; esac
  sleep 2
done
curl -sf "http://$http/v1/jobs/$job" | json "['state']" | grep -q succeeded || exit 1
objects=$(curl -sf "http://$http/v1/scenes/$scene/objects?level=large")
echo "$objects" | python3 -c "import json,sys; o=json.load(sys.stdin)['objects']; print(len(o), 'large objects; biggest:', sorted(o, key=lambda x: -x['gaussian_count'])[:3])"
first=$(echo "$objects" | python3 -c "import json,sys; o=json.load(sys.stdin)['objects']; print(max(o, key=lambda x: x['gaussian_count'])['object_id'])")
curl -sf -o mask_large_${first}_frame0.png \
  "http://$http/v1/scenes/$scene/objects/large/$first/mask.png?frame_index=0&max_side=512"
echo "mask of large object $first in frame 0: ./mask_large_${first}_frame0.png"
echo "artifacts: ./data/blobs/jobs/$job/output/ (scene.ply, labels.npy, cameras.json, objects.json, metrics.json)"
echo "query it: target/release/segsplat query $scene \"a figurine\" --frame 0 (with models.dir set)"
