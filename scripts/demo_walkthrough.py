#!/usr/bin/env python3
"""The client half of scripts/demo.sh: upload, follow the job's event stream with a progress bar
per stage, then a summary table and one mask. Standard library only, so the demo needs nothing
installed beyond Python itself."""

import argparse
import io
import json
import os
import sys
import tarfile
import time
import urllib.error
import urllib.request

BAR_WIDTH = 30
# What a stage's steps count, for the bar.
UNITS = {"segment": "views", "train": "steps"}


def request(url, data=None, content_type=None, method=None):
    headers = {"content-type": content_type} if content_type else {}
    req = urllib.request.Request(url, data=data, headers=headers, method=method)
    try:
        with urllib.request.urlopen(req) as response:
            return response.read()
    except urllib.error.HTTPError as error:
        body = error.read().decode(errors="replace")
        sys.exit(f"{method or ('POST' if data else 'GET')} {url}: {error.code} {body}")


def get_json(url):
    return json.loads(request(url))


def post_json(url, payload):
    return json.loads(request(url, json.dumps(payload).encode(), "application/json"))


def dataset_archive(dataset):
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
        for name in sorted(os.listdir(dataset)):
            archive.add(os.path.join(dataset, name), arcname=name)
    return buffer.getvalue()


def duration(seconds):
    seconds = int(round(seconds))
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    if seconds >= 60:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds}s"


class ProgressView:
    """One bar per stage. On a terminal the bar is redrawn in place; otherwise a line is printed
    when a stage starts, at every tenth of it, and when it ends (never the same line twice)."""

    def __init__(self):
        self.tty = sys.stdout.isatty()
        self.stage = None
        self.last_line = None
        self.last_tenth = -1
        # Seconds from the job's submission to each stage's first event, by stage, in order, and
        # to the job's final state (set by `finish`).
        self.started = time.monotonic()
        self.stage_starts = {}
        self.ended = 0.0

    def line(self, progress):
        stage = progress.get("stage", "")
        metrics = progress.get("metrics") or {}
        if metrics.get("skipped_no_clip_model"):
            # Not a stalled bar: the stage has nothing to do.
            return (f"{stage:<9} skipped: no CLIP model is configured, so the objects are stored "
                    "without embeddings and text queries are refused (`segsplat models init` "
                    "sets one up)")
        step, total = progress.get("step", 0), max(progress.get("total_steps", 0), 1)
        filled = int(BAR_WIDTH * min(step / total, 1.0))
        bar = "#" * filled + "-" * (BAR_WIDTH - filled)
        shown = []
        for name, label, fmt in (("loss", "loss", "{:.4f}"), ("psnr", "PSNR", "{:.1f} dB"),
                                 ("gaussians", "Gaussians", "{:.0f}")):
            if name in metrics:
                shown.append(f"{label} {fmt.format(metrics[name])}")
        eta = progress.get("eta_secs")
        if eta is not None and step < total:
            shown.append(f"ETA {duration(eta)}")
        unit = UNITS.get(stage, "")
        return f"{stage:<9} [{bar}] {step}/{total} {unit}  " + "  ".join(shown)

    def note(self, text):
        """A line of its own between the bars (a warning, a word about the stage)."""
        if self.tty and self.stage is not None:
            sys.stdout.write("\n")
            self.stage, self.last_line = None, None
        print(text, flush=True)

    def update(self, progress):
        stage = progress.get("stage", "")
        self.stage_starts.setdefault(stage, time.monotonic() - self.started)
        text = self.line(progress)
        if text == self.last_line:
            return
        total = max(progress.get("total_steps", 0), 1)
        tenth = int(10 * progress.get("step", 0) / total)
        if stage != self.stage:
            if self.tty and self.stage is not None:
                sys.stdout.write("\n")
            self.stage, self.last_tenth = stage, -1
        if self.tty:
            sys.stdout.write("\r\033[K" + text)
            sys.stdout.flush()
        elif tenth != self.last_tenth:
            print(text, flush=True)
        self.last_tenth = tenth
        self.last_line = text

    def finish(self):
        if self.tty and self.stage is not None:
            sys.stdout.write("\n")
            sys.stdout.flush()
        self.ended = time.monotonic() - self.started

    def stage_times(self):
        """Each stage's wall time, from its first event to the next stage's (the last one's to
        the job's end): where a job's time goes, e.g. "segment 3s, train 2m50s"."""
        starts = list(self.stage_starts.items())
        ends = [start for _, start in starts[1:]] + [self.ended]
        return ", ".join(f"{stage} {duration(end - start)}"
                         for (stage, start), end in zip(starts, ends))


def follow_job(url, job_id, view, frame_count=None):
    """Follows the job's Server-Sent Events until its final state; returns that state's payload.
    Warnings (and the note that the frames were undistorted) are printed as they come; with
    `frame_count`, the first segment report says how many frames are held out."""
    final = None
    split_told = False
    with urllib.request.urlopen(f"{url}/v1/jobs/{job_id}/events") as stream:
        data = []
        for raw in stream:
            line = raw.decode().rstrip("\n")
            if line.startswith("data:"):
                data.append(line[5:].strip())
                continue
            if line or not data:
                continue
            event = json.loads("\n".join(data))
            data = []
            payload = event.get("payload") or {}
            kind = event.get("kind")
            if kind == "progress":
                stage = payload.get("stage")
                total = payload.get("total_steps", 0)
                if not split_told and frame_count and stage == "segment":
                    held_out = frame_count - total
                    split_told = True
                    if held_out > 0:
                        view.note(f"{total} of the {frame_count} frames train; {held_out} "
                                  f"{'is' if held_out == 1 else 'are'} held out to measure "
                                  "the held-out PSNR / SSIM at the end")
                view.update(payload)
            elif kind in ("warning", "undistorted"):
                label = "warning" if kind == "warning" else "note"
                view.note(f"{label}: {payload.get('message') or json.dumps(payload)}")
            elif event.get("kind") == "state" and payload.get("state") in (
                    "succeeded", "failed", "cancelled"):
                final = payload
                break
    view.finish()
    return final


def table(headers, rows):
    widths = [max(len(str(cell)) for cell in column) for column in zip(headers, *rows)]
    lines = ["  ".join(str(cell).ljust(width) for cell, width in zip(headers, widths))]
    lines.append("  ".join("-" * width for width in widths))
    for row in rows:
        lines.append("  ".join(str(cell).ljust(width) for cell, width in zip(row, widths)))
    return "\n".join(line.rstrip() for line in lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--url", required=True)
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--steps", required=True,
                        help='training steps at 256 px, "auto" (256 px, steps sized by the '
                             'job from the scene) or "defaults": the job\'s own config '
                             '(steps from the scene, full resolution)')
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    url, out = args.url, args.out
    started = time.monotonic()
    if args.steps == "defaults":
        config, settings = {}, "the job's defaults"
    elif args.steps == "auto":
        config = {"max_resolution": 256, "checkpoint_every": 0}
        settings = "steps from the scene at 256 px"
    elif args.steps.isdigit():
        config = {"steps": int(args.steps), "max_resolution": 256, "checkpoint_every": 0}
        settings = f"{args.steps} steps at 256 px"
    else:
        sys.exit(f'STEPS must be a number of steps, "auto" or "defaults", not {args.steps!r}')

    print(f"uploading {args.dataset} ...", flush=True)
    scene = json.loads(request(f"{url}/v1/scenes", dataset_archive(args.dataset),
                               "application/gzip"))
    size = ", ".join(f"{w}x{h}" for w, h in scene.get("resolutions", []))
    print(f"scene {scene['id']}: {scene['format']}, {scene['frame_count']} frames ({size}), "
          f"{scene['sparse_point_count']} sparse points", flush=True)

    job = post_json(f"{url}/v1/scenes/{scene['id']}/jobs",
                    {"kind": "segment_then_splat", "config": config})
    print(f"job {job['id']}: segment_then_splat, {settings}", flush=True)
    view = ProgressView()
    final = follow_job(url, job["id"], view, scene["frame_count"])
    if not final or final.get("state") != "succeeded":
        reason = (final or {}).get("error") or "the event stream ended early"
        sys.exit(f"job {job['id']} {(final or {}).get('state', 'ended')}: {reason}")

    objects = get_json(f"{url}/v1/scenes/{scene['id']}/objects")["objects"]
    with open(os.path.join(out, "objects.json"), "w") as file:
        json.dump(objects, file, indent=2)
    counts = {level: [o for o in objects if o["level"] == level]
              for level in ("small", "middle", "large")}
    print("\nObjects found")
    print(table(["level", "objects", "Gaussians"],
                [[level, len(found), sum(o["gaussian_count"] for o in found)]
                 for level, found in counts.items()]))
    large = sorted(counts["large"], key=lambda o: -o["gaussian_count"])
    if large:
        print("\nLargest objects (large level)")
        print(table(["id", "Gaussians", "centroid (x, y, z)"],
                    [[o["object_id"], o["gaussian_count"],
                      "({:.2f}, {:.2f}, {:.2f})".format(*o["centroid"])] for o in large[:5]]))
        first = large[0]["object_id"]
        mask_path = os.path.join(out, f"mask_large_{first}_frame0.png")
        with open(mask_path, "wb") as file:
            file.write(request(f"{url}/v1/scenes/{scene['id']}/objects/large/{first}/mask.png"
                               "?frame_index=0&max_side=512"))
    metrics = json.loads(request(f"{url}/v1/scenes/{scene['id']}/trained/metrics.json"))
    held_out = metrics.get("held_out") or {}
    print("\nSummary")
    rows = [["scene", scene["id"]], ["job", job["id"]],
            ["wall time", duration(time.monotonic() - started)],
            ["stage times", view.stage_times()]]
    if held_out:
        rows.append(["held-out PSNR / SSIM",
                     f"{held_out.get('psnr', 0):.2f} dB / {held_out.get('ssim', 0):.3f} "
                     f"over {held_out.get('views', 0)} views"])
    if large:
        rows.append(["mask of the largest object, frame 0", mask_path])
    rows += [["objects table", os.path.join(out, "objects.json")],
             ["trained files", os.path.join(out, "data", "blobs", "jobs", job["id"], "output")],
             ["server log", os.path.join(out, "server.log")]]
    rows.append(["in the console", f"{url}/#/scenes/{scene['id']}"])
    print(table(["what", "where"], rows))
    with open(os.path.join(out, "summary.txt"), "w") as file:
        file.write(table(["what", "where"], rows) + "\n")
    print(f"\nTo look at the result, open {url}/#/scenes/{scene['id']} in a browser (the web "
          "console: the splats in 3D, the objects, text queries, masks) while the server runs.")


if __name__ == "__main__":
    main()
