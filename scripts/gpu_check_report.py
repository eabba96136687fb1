#!/usr/bin/env python3
"""The report half of scripts/gpu_check.sh: reads the steps the run recorded (one folder per step:
kind, name, command, timeout, rc, seconds, stdout, stderr, or `skipped`) and writes one JSON
report, then prints its figures. The shell script calls it after every step, so a run cut short
still leaves a report of what finished. Standard library only: the GPU host may have nothing
else."""

import argparse
import json
import os
import re
import sys

TAIL_CHARS = 4000


def read(path, default=None):
    try:
        with open(path, errors="replace") as file:
            return file.read()
    except OSError:
        return default


def tail(text, chars=TAIL_CHARS):
    text = text or ""
    return text if len(text) <= chars else "..." + text[-chars:]


def seconds_of(text):
    """'2m41s', '1h02m', '10s' (the demo's durations) as seconds, or None."""
    match = re.fullmatch(r"(?:(\d+)h)?(?:(\d+)m)?(?:(\d+)s)?", text.strip())
    if not match or not any(match.groups()):
        return None
    hours, minutes, secs = (int(group or 0) for group in match.groups())
    return hours * 3600 + minutes * 60 + secs


def base_result(step):
    result = {"name": step["name"]}
    # A dry run's steps keep the command and timeout they would have run with.
    if "command" in step:
        result.update(command=step["command"].strip(), timeout_seconds=step.get("timeout"))
    if step.get("skipped") is not None:
        result.update(status="skipped", reason=step["skipped"].strip())
        return result
    rc = step.get("rc")
    result.update(exit_code=rc, seconds=step.get("seconds"))
    if rc is None:
        result["status"] = "running"
    elif rc in (124, 137):
        # `timeout` exits 124 when it stopped the command, 137 when it had to kill it.
        result["status"] = "timeout"
    else:
        result["status"] = "passed" if rc == 0 else "failed"
    return result


def test_result(step):
    result = base_result(step)
    if result["status"] == "skipped":
        return result
    output = (step.get("stdout") or "") + "\n" + (step.get("stderr") or "")
    counts = {"passed": 0, "failed": 0, "ignored": 0}
    for match in re.finditer(r"test result: \w+\. (\d+) passed; (\d+) failed; (\d+) ignored",
                             output):
        for key, value in zip(("passed", "failed", "ignored"), match.groups()):
            counts[key] += int(value)
    result.update(counts)
    result["failures"] = sorted(set(re.findall(r"^test (\S+) \.\.\. FAILED", output, re.M)))
    # libtest names the tests that outlast 60 s: what a timed-out binary was still running.
    result["slow"] = sorted(set(re.findall(r"^test (\S+) has been running for over", output,
                                           re.M)))
    if result["status"] != "passed":
        result["tail"] = tail(output)
    if result["status"] == "timeout":
        # The tests that got no result before the cut, as gpu_check.sh found them for its rerun;
        # with one test at a time, the one it was cut in, which libtest names as it starts
        # ("test NAME ... " with nothing after).
        if step.get("unfinished"):
            result["unfinished"] = step["unfinished"].split()
        started = re.findall(r"^test (\S+) \.\.\. *$", step.get("stdout") or "", re.M)
        if started:
            result["cut_in"] = started[-1]
    return result


def bench_result(step):
    result = base_result(step)
    if result["status"] == "skipped":
        return result
    stdout = (step.get("stdout") or "").strip()
    report = None
    if stdout:
        # The JSON object is the last thing printed; anything before it is not part of it.
        start = stdout.find("{")
        try:
            report = json.loads(stdout[start:]) if start >= 0 else None
        except ValueError:
            report = None
    if report is not None:
        result["report"] = report
    elif result["status"] == "passed":
        result["status"] = "failed"
        result["error"] = "no JSON report on stdout"
    if result["status"] != "passed":
        result["tail"] = tail((step.get("stderr") or "") + "\n" + stdout)
    return result


def demo_rows(summary):
    """The demo's summary table (`what  where` columns) as a dict."""
    rows = {}
    for line in (summary or "").splitlines()[2:]:
        parts = re.split(r"\s{2,}", line.strip(), maxsplit=1)
        if len(parts) == 2:
            rows[parts[0]] = parts[1]
    return rows


def job_result(step):
    result = base_result(step)
    result["steps"] = step.get("job_steps", "").strip()
    if result["status"] == "skipped":
        return result
    stdout = step.get("stdout") or ""
    demo_out = (step.get("demo_out") or "").strip()
    rows = demo_rows(read(os.path.join(demo_out, "summary.txt"), "")) if demo_out else {}
    if "wall time" in rows:
        result["wall_time"] = rows["wall time"]
        result["wall_seconds"] = seconds_of(rows["wall time"])
    if "stage times" in rows:
        stages = {}
        for part in rows["stage times"].split(", "):
            stage, _, took = part.rpartition(" ")
            stages[stage] = {"time": took, "seconds": seconds_of(took)}
        result["stage_times"] = stages
    held_out = re.match(r"([\d.]+) dB / ([\d.]+) over (\d+) views",
                        rows.get("held-out PSNR / SSIM", ""))
    if held_out:
        result.update(psnr=float(held_out.group(1)), ssim=float(held_out.group(2)),
                      held_out_views=int(held_out.group(3)))
    trained = rows.get("trained files")
    if trained:
        metrics = read(os.path.join(trained, "metrics.json"))
        if metrics:
            try:
                result["metrics"] = json.loads(metrics)
            except ValueError:
                pass
    objects = read(os.path.join(demo_out, "objects.json")) if demo_out else None
    if objects:
        try:
            found = json.loads(objects)
            result["objects"] = {level: sum(1 for o in found if o.get("level") == level)
                                 for level in ("small", "middle", "large")}
        except ValueError:
            pass
    # The demo prints a progress line at every tenth of a stage: the last ones say how far a
    # job that ran out of time got, and at what rate.
    progress = [line.strip() for line in stdout.splitlines()
                if re.match(r"(segment|train|evaluate|embed|persist)\s+\[", line.strip())]
    if progress:
        result["last_progress"] = progress[-1]
        result["progress"] = progress[-12:]
    if result["status"] == "passed" and "psnr" not in result:
        result["status"] = "failed"
        result["error"] = "the demo printed no held-out PSNR"
    if result["status"] != "passed":
        server_log = read(os.path.join(demo_out, "server.log"), "") if demo_out else ""
        result["tail"] = tail((step.get("stderr") or "") + "\n" + stdout)
        result["server_log_tail"] = tail(server_log, 2000)
    return result


def adapters_result(step):
    result = base_result(step)
    if result["status"] == "skipped":
        return result
    try:
        result["adapters"] = json.loads(step.get("stdout") or "")
    except ValueError:
        result["tail"] = tail((step.get("stderr") or "") + "\n" + (step.get("stdout") or ""))
        if result["status"] == "passed":
            result["status"] = "failed"
    return result


def load_step(path):
    step = {"name": os.path.basename(path).split("-", 1)[-1]}
    for field in ("kind", "name", "command", "stdout", "stderr", "skipped", "demo_out",
                  "job_steps", "env", "unfinished"):
        value = read(os.path.join(path, field))
        if value is not None:
            step[field] = value if field in ("stdout", "stderr", "command") else value.strip()
    for field, kind in (("rc", int), ("timeout", int), ("seconds", float)):
        value = read(os.path.join(path, field))
        if value is not None and value.strip():
            step[field] = kind(value.strip())
    return step


def read_meta(folder):
    """The run's own fields, one file each: JSON where the file parses as JSON, else text."""
    meta = {}
    for name in sorted(os.listdir(folder)) if os.path.isdir(folder) else []:
        text = read(os.path.join(folder, name), "").strip()
        try:
            meta[name] = json.loads(text)
        except ValueError:
            meta[name] = text
    return meta


def assemble(work):
    meta = read_meta(os.path.join(work, "meta"))
    steps_dir = os.path.join(work, "steps")
    names = sorted(os.listdir(steps_dir)) if os.path.isdir(steps_dir) else []
    tests, benches, adapters_tries, job = [], [], [], None
    for name in names:
        step = load_step(os.path.join(steps_dir, name))
        kind = step.get("kind")
        if kind == "test":
            tests.append(test_result(step))
        elif kind == "test-serial" and tests and tests[-1]["name"] == step.get("name"):
            # The failed or timed-out binary's rerun with one test at a time (gpu_check.sh):
            # kept with it, not counted again.
            rerun = test_result(step)
            tests[-1]["serial_rerun"] = {key: rerun[key] for key in
                                         ("status", "passed", "failed", "failures", "cut_in",
                                          "seconds")
                                         if key in rerun}
        elif kind == "bench":
            benches.append(bench_result(step))
        elif kind == "adapters":
            adapters_tries.append(adapters_result(step))
        elif kind == "job":
            job = job_result(step)
    listed = (adapters_tries[-1].get("adapters") or []) if adapters_tries else []
    ran = [t for t in tests if t["status"] != "skipped"]
    return {
        "schema": 1,
        "pack": meta.pop("pack", None),
        "run": meta,
        # The first is the one the engine picks (hardware adapters are listed first).
        "adapter": listed[0] if listed else None,
        "adapters": listed,
        "adapter_tries": [{key: value for key, value in attempt.items() if key != "adapters"}
                          for attempt in adapters_tries],
        "tests": {
            "binaries": tests,
            "binaries_passed": sum(1 for t in ran if t["status"] == "passed"),
            "binaries_failed": sum(1 for t in ran if t["status"] != "passed"),
            "passed": sum(t.get("passed", 0) for t in ran),
            "failed": sum(t.get("failed", 0) for t in ran),
            "ignored": sum(t.get("ignored", 0) for t in ran),
        },
        "benches": benches,
        "job": job,
    }


# The figures printed for every bench: (report key, unit, format).
HEADLINE = (("steps_per_sec", "steps/s", "{:.2f}"), ("psnr", "dB", "{:.2f}"),
            ("gaussians_end", "Gaussians", "{}"))


def headline(bench):
    found = bench.get("report") or {}
    parts = [f"{fmt.format(found[key])} {label}" for key, label, fmt in HEADLINE if key in found]
    ratio = (found.get("plain_baseline") or {}).get("step_time_ratio")
    if ratio is None:
        ratio = (found.get("deformation") or {}).get("step_time_ratio")
    if ratio is not None:
        parts.append(f"step ratio {ratio:.2f}x")
    profile = found.get("kernel_profile") or {}
    if "gpu_ms_per_step" in profile:
        parts.append(f"GPU {profile['gpu_ms_per_step']:.2f} ms/step")
    parts.extend(host_figures(found.get("host") or {}))
    parts.extend(timeline_figures(profile.get("timeline") or {}))
    return ", ".join(parts)


# The GPU's timeline over a sample of steps (`segsplat_gpu::BusySummary`): (key, label, format).
TIMELINE = (("pass_ms_per_step", "GPU in passes ms/step", "{:.3f}"),
            ("kernel_ms_per_step", "in kernels", "{:.3f}"),
            ("idle_ms_per_step", "GPU idle ms/step", "{:.3f}"),
            ("longest_gap_ms", "longest gap ms", "{:.2f}"))


def timeline_figures(timeline):
    return labelled(timeline, TIMELINE)


# The host's side of a step (issue 38, item 4), where a report has it: (key, label, format).
HOST = (("host_ms_per_step", "host ms/step", "{:.3f}"),
        ("finish_ms_per_step", "of it in finish", "{:.3f}"),
        ("submit_ms_per_step", "submit ms/step", "{:.3f}"),
        ("compute_passes_per_step", "passes/step", "{:.1f}"),
        ("dispatches_per_step", "dispatches/step", "{:.1f}"),
        ("gpu_busy_fraction", "GPU busy", "{:.2f}"),
        ("partial_filter_seconds", "partial-mask filter s", "{:.2f}"),
        ("clamped_renders", "clamped renders", "{}"))


def host_figures(host):
    return labelled(host, HOST)


def labelled(values, table):
    """Each (key, label, format) of `table` whose value `values` has, as "label value"."""
    return [f"{label} {fmt.format(values[key])}" for key, label, fmt in table
            if isinstance(values.get(key), (int, float))]


def print_summary(report):
    adapter = report.get("adapter") or {}
    print(f"adapter: {adapter.get('name', '?')} ({adapter.get('backend', '?')}, "
          f"{adapter.get('device_type', '?')})")
    tests = report["tests"]
    print(f"tests: {tests['binaries_passed']} binaries passed, {tests['binaries_failed']} not; "
          f"{tests['passed']} tests passed, {tests['failed']} failed")
    for test in tests["binaries"]:
        if test["status"] != "passed":
            rerun = test.get("serial_rerun")
            serial = ""
            if rerun:
                cut = f", cut in {rerun['cut_in']}" if "cut_in" in rerun else ""
                serial = f" (one test at a time: {rerun['status']}{cut})"
            left = test.get("unfinished")
            left = f"unfinished: {' '.join(left)}" if left else ""
            print(f"  {test['name']}: {test['status']} {test.get('reason', '')}"
                  f"{' '.join(test.get('failures', []))}{left}{serial}")
    for bench in report["benches"]:
        took = f" in {bench['seconds']:.0f} s" if bench.get("seconds") is not None else ""
        print(f"bench {bench['name']}: {bench['status']}{took} {headline(bench)}".rstrip())
    job = report.get("job")
    if job:
        figures = [f"{job[key]}" for key in ("wall_time",) if key in job]
        if "psnr" in job:
            figures.append(f"{job['psnr']:.2f} dB / {job['ssim']:.3f}")
        if "stage_times" in job:
            figures.append(", ".join(f"{stage} {value['time']}"
                                     for stage, value in job["stage_times"].items()))
        metrics = job.get("metrics") or {}
        figures.extend(host_figures(metrics.get("training") or {}))
        figures.extend(timeline_figures((metrics.get("training") or {}).get("gpu_timeline") or {}))
        masks = (metrics.get("segment") or {}).get("masks_seconds")
        if isinstance(masks, (int, float)):
            figures.append(f"masks {masks:.1f} s")
        if job["status"] != "passed" and "last_progress" in job:
            figures.append(f"last: {job['last_progress']}")
        print(f"job ({job.get('steps', '')}): {job['status']} " + "; ".join(figures))


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--work", required=True,
                        help="the run's work folder: meta/ (the run's fields) and steps/")
    parser.add_argument("--out", required=True, help="where to write the report")
    parser.add_argument("--summary", action="store_true", help="also print the figures")
    args = parser.parse_args()
    report = assemble(args.work)
    partial = args.out + ".partial"
    with open(partial, "w") as file:
        json.dump(report, file, indent=2)
        file.write("\n")
    # Replaced whole, so a reader never sees half a report.
    os.replace(partial, args.out)
    if args.summary:
        print_summary(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
