#!/usr/bin/env python3
"""Held-out quality against training length through a running `segsplat serve` (issue 38, item
2: more training must never make a scene worse). Uploads a dataset once, then runs one
segment_then_splat job per step count, one after another so each has the machine to itself,
and prints each job's held-out PSNR / SSIM, its curve (held-out PSNR every `held_out_every`
steps) and its wall time, following each job's events with the demo's progress bars. Standard
library only (scripts/demo_walkthrough.py's client helpers).

    python3 scripts/schedule_check.py --url http://127.0.0.1:8080 --dataset DIR \\
        --steps 3000,6000,15000 [--max-resolution 256] [--seed 42] [--config '{"...": ...}'] \\
        [--json report.json]

`--steps` takes numbers, or `scene` for the job's own scene-sized steps (a config without
`steps`). `--config` is merged into every job's config: `{"schedule_steps": null}` runs the
stretched schedule a job had before issue 38 (stages laid out over all of its steps).
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from demo_walkthrough import (  # noqa: E402
    ProgressView, dataset_archive, follow_job, post_json, request)


def run_job(url, scene_id, config):
    started = time.monotonic()
    job = post_json(f"{url}/v1/scenes/{scene_id}/jobs",
                    {"kind": "segment_then_splat", "config": config})
    final = follow_job(url, job["id"], ProgressView())
    wall = time.monotonic() - started
    if not final or final.get("state") != "succeeded":
        reason = (final or {}).get("error") or "the event stream ended early"
        sys.exit(f"job {job['id']} {(final or {}).get('state', 'ended')}: {reason}")
    metrics = json.loads(request(f"{url}/v1/scenes/{scene_id}/trained/metrics.json"))
    training = metrics.get("training") or {}
    held_out = metrics.get("held_out") or {}
    return {
        "job": job["id"],
        "config": config,
        "steps": training.get("steps"),
        "wall_seconds": round(wall, 1),
        "training_seconds": training.get("seconds"),
        "held_out_psnr": held_out.get("psnr"),
        "held_out_ssim": held_out.get("ssim"),
        "gpu_busy_fraction": training.get("gpu_busy_fraction"),
        "job_overhead_ratio": training.get("job_overhead_ratio"),
        "clamped_renders": training.get("clamped_renders"),
        "curve": [[point["step"], round(point["psnr"], 2), round(point["train_seconds"], 1),
                   point["gaussians"]] for point in training.get("held_out_curve", [])],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--url", required=True)
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--steps", default="scene,6000,15000",
                        help="comma-separated step counts, or 'scene' for the job's own")
    parser.add_argument("--max-resolution", type=int)
    parser.add_argument("--seed", type=int, default=42)
    parser.add_argument("--held-out-every", type=int, default=500)
    parser.add_argument("--config", default="{}", help="JSON merged into every job's config")
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()
    url = args.url.rstrip("/")
    extra = json.loads(args.config)
    if not isinstance(extra, dict):
        sys.exit("--config must be a JSON object")

    scene = json.loads(request(f"{url}/v1/scenes", dataset_archive(args.dataset),
                               "application/gzip"))
    print(f"scene {scene['id']}: {scene['frame_count']} frames", flush=True)
    results = []
    for steps in args.steps.split(","):
        config = {"seed": args.seed, "checkpoint_every": 0,
                  "held_out_every": args.held_out_every}
        if steps != "scene":
            if not steps.isdigit():
                sys.exit(f"--steps: '{steps}' is neither a number nor 'scene'")
            config["steps"] = int(steps)
        if args.max_resolution:
            config["max_resolution"] = args.max_resolution
        config.update(extra)
        result = run_job(url, scene["id"], config)
        curve = " ".join(f"{step}:{psnr:.2f}" for step, psnr, _, _ in result["curve"])
        print(f"{result['steps']} steps: held-out {result['held_out_psnr']:.2f} dB / "
              f"{result['held_out_ssim']:.3f}, wall {result['wall_seconds']} s "
              f"(training {result['training_seconds']}); curve {curve}", flush=True)
        results.append(result)
        if args.json:
            with open(args.json, "w") as file:
                json.dump({"scene": scene["id"], "dataset": args.dataset, "jobs": results},
                          file, indent=2)


if __name__ == "__main__":
    main()
