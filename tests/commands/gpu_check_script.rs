//! `scripts/gpu_check.sh` without a GPU or a real pack: its options, the dry run's plan, and a run
//! over a stub pack (a `segsplat` and test binaries that are shell scripts, a demo that writes
//! the real demo's summary) whose one JSON report must hold each step's result: passed, failed
//! and timed-out test binaries with their counts, every bench's JSON, and the job's wall time,
//! PSNR / SSIM and stage times.

use std::path::Path;
use std::process::{Command, Output};

use serde_json::{Value, json};

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/gpu_check.sh");

fn gpu_check(args: &[&str], out: &Path, envs: &[(&str, &Path)]) -> Output {
    let mut command = Command::new("bash");
    // A SEGSPLAT_BIN of the caller's (a GPU host's) would stand in for the missing pack.
    command
        .arg(SCRIPT)
        .args(args)
        .env("OUT", out)
        .env_remove("SEGSPLAT_BIN");
    for (name, value) in envs {
        command.env(name, value);
    }
    command.output().expect("run bash")
}

fn report(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("gpu_check.json")).expect("the report");
    serde_json::from_str(&text).expect("the report is JSON")
}

fn write_executable(path: &Path, text: &str) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

#[test]
fn help_and_bad_arguments() {
    let out = tempfile::tempdir().unwrap();
    let help = gpu_check(&["--help"], out.path(), &[]);
    assert!(help.status.success(), "{help:?}");
    let text = String::from_utf8_lossy(&help.stdout);
    for word in ["pack", "run", "--quick", "--dry-run", "--budget"] {
        assert!(text.contains(word), "{word}: {text}");
    }
    for (args, says) in [
        (&[][..], "Usage"),
        (&["deploy"][..], "unknown mode"),
        (&["run", "--bogus"][..], "--bogus"),
        (&["run", "--job", "12x"][..], "12x"),
        (&["run", "--scale", "fast"][..], "--scale"),
        (&["run", "a", "b"][..], "one DATASET_DIR"),
        (&["pack", "extra"][..], "only --dataset"),
    ] {
        let refused = gpu_check(args, out.path(), &[]);
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
    assert!(!out.path().join("gpu_check.json").exists(), "no report");
}

#[test]
fn a_dry_run_plans_every_step_and_writes_the_report_shape() {
    let out = tempfile::tempdir().unwrap();
    let no_pack = out.path().join("no-pack");
    let dataset = out.path().join("dataset");
    std::fs::create_dir(&dataset).unwrap();
    let run = gpu_check(
        &[
            "run",
            "--dry-run",
            "--quick",
            "--pack",
            no_pack.to_str().unwrap(),
            dataset.to_str().unwrap(),
        ],
        out.path(),
        &[],
    );
    assert!(run.status.success(), "{run:?}");
    let report = report(out.path());
    assert_eq!(report["run"]["dry_run"], true);
    assert_eq!(report["run"]["quick"], true);
    assert_eq!(report["run"]["dataset"], dataset.to_str().unwrap());
    let tests = report["tests"]["binaries"].as_array().unwrap();
    let names: Vec<&str> = tests.iter().map(|t| t["name"].as_str().unwrap()).collect();
    for name in [
        "raster_gpu",
        "train_synthetic",
        "train_dynamic",
        "object_step_batched",
    ] {
        assert!(names.contains(&name), "{name}: {names:?}");
    }
    assert!(tests.iter().all(|t| t["status"] == "skipped"), "{tests:?}");
    let benches = report["benches"].as_array().unwrap();
    assert_eq!(benches.len(), 5, "{benches:?}");
    // --quick: a quarter of each bench's steps.
    let plain = benches[0]["command"].as_str().unwrap();
    assert!(
        plain.contains("bench") && plain.contains("--steps 500 --max-resolution 1000"),
        "{plain}"
    );
    assert_eq!(report["job"]["steps"], "2000");
    assert_eq!(report["job"]["status"], "skipped");
}

const STUB_SEGSPLAT: &str = r#"#!/bin/sh
case $1 in
  adapters) echo '[{"name": "Stub GPU", "backend": "Vulkan", "device_type": "DiscreteGpu", "is_software": false}]' ;;
  bench) echo "progress on stdout before the report"; echo '{"adapter": "Stub GPU", "steps_per_sec": 125.5, "psnr": 21.25, "gaussians_end": 1000}' ;;
  *) exit 3 ;;
esac
"#;

const STUB_PASSES: &str = r#"#!/bin/sh
# The packed CLI must be named, and be the unpacked one.
[ -x "$SEGSPLAT_BIN" ] || { echo "SEGSPLAT_BIN=$SEGSPLAT_BIN"; exit 101; }
[ -z "$SEGSPLAT_SKIP_GPU_TESTS" ] || { echo "skipping allowed"; exit 101; }
echo "test renders ... ok"
echo "test trains ... ok"
echo "test result: ok. 2 passed; 0 failed; 1 ignored; 0 measured; 0 filtered out; finished in 0.01s"
"#;

const STUB_FAILS: &str = r#"#!/bin/sh
echo "test fine ... ok"
echo "test broken_on_gpu ... FAILED"
echo "test result: FAILED. 1 passed; 1 failed; 0 ignored; 0 measured; 0 filtered out; finished in 0.01s"
exit 101
"#;

/// One test finishes and two never do; listed, and rerun with only those two, one at a time.
const STUB_HANGS: &str = r#"#!/bin/sh
case "$*" in
  "--list --format terse") printf 'quick: test\nstuck: test\nafter: test\n'; exit 0 ;;
  "--test-threads=1 --exact stuck after") printf 'test after ... ok\ntest stuck ... '; exec sleep 30 ;;
  "") echo "test quick ... ok"; exec sleep 30 ;;
  *) echo "unexpected arguments: $*"; exit 2 ;;
esac
"#;

/// Writes what scripts/demo.sh leaves: a summary table, the objects, the trained metrics.
const STUB_DEMO: &str = r#"#!/bin/bash
set -euo pipefail
out=$SEGSPLAT_DEMO_OUT
mkdir -p "$out/trained"
echo 'train     [###############---------------] 20/40 steps  loss 0.1000'
echo 'train     [##############################] 40/40 steps  loss 0.0500  PSNR 19.3 dB'
echo '{"held_out": {"psnr": 19.29, "ssim": 0.785, "views": 3}}' >"$out/trained/metrics.json"
echo '[{"level": "small"}, {"level": "small"}, {"level": "large"}]' >"$out/objects.json"
cat >"$out/summary.txt" <<EOF
what                  where
--------------------  -----
job                   j1
wall time             1m05s
stage times           segment 3s, train 1m00s, evaluate 1s
held-out PSNR / SSIM  19.29 dB / 0.785 over 3 views
trained files         $out/trained
EOF
"#;

#[test]
fn a_run_over_a_stub_pack_reports_every_step() {
    let work = tempfile::tempdir().unwrap();
    let stage = work.path().join("stage");
    write_executable(&stage.join("bin/segsplat"), STUB_SEGSPLAT);
    write_executable(&stage.join("tests/passes"), STUB_PASSES);
    write_executable(&stage.join("tests/fails"), STUB_FAILS);
    write_executable(&stage.join("tests/hangs"), STUB_HANGS);
    let pack = work.path().join("pack");
    std::fs::create_dir(&pack).unwrap();
    std::fs::write(
        pack.join("manifest.json"),
        r#"{"commit": "stub", "tests": ["passes", "fails", "hangs"]}"#,
    )
    .unwrap();
    // The pack's format as `pack` writes it, by the tool `run` reads it with.
    let packed = Command::new("python3")
        .args([
            "-c",
            "import sys, tarfile\n\
             with tarfile.open(sys.argv[1], 'w:xz') as t:\n    \
             t.add(sys.argv[2] + '/bin', 'bin'); t.add(sys.argv[2] + '/tests', 'tests')",
        ])
        .arg(pack.join("binaries.tar.xz"))
        .arg(&stage)
        .output()
        .unwrap();
    assert!(packed.status.success(), "{packed:?}");
    let demo = work.path().join("demo.sh");
    write_executable(&demo, STUB_DEMO);
    let dataset = work.path().join("dataset");
    std::fs::create_dir(&dataset).unwrap();
    let out = work.path().join("out");
    std::fs::create_dir(&out).unwrap();

    let run = gpu_check(
        &[
            "run",
            "--pack",
            pack.to_str().unwrap(),
            "--test-timeout",
            "1",
            "--job",
            "40",
            dataset.to_str().unwrap(),
        ],
        &out,
        &[("SEGSPLAT_GPU_CHECK_DEMO", &demo)],
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    // A failed test binary fails the run, and every later step still ran.
    assert_eq!(run.status.code(), Some(1), "{run:?}");
    let report = report(&out);
    assert_eq!(report["run"]["finished"], true, "{stdout}");
    assert_eq!(report["pack"]["commit"], "stub");
    assert_eq!(report["adapter"]["name"], "Stub GPU");

    let tests = &report["tests"];
    let by_name = |name: &str| {
        tests["binaries"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["name"] == name)
            .unwrap_or_else(|| panic!("{name}: {tests}"))
            .clone()
    };
    assert_eq!(by_name("passes")["status"], "passed", "{tests}");
    assert_eq!(by_name("passes")["passed"], 2);
    assert_eq!(by_name("passes")["ignored"], 1);
    assert_eq!(by_name("fails")["status"], "failed");
    assert_eq!(by_name("fails")["failures"][0], "broken_on_gpu");
    // A failed binary runs again one test at a time, kept with it and not counted twice; a
    // timed-out one runs again with only its unfinished tests, which names the one it hangs in.
    assert_eq!(
        by_name("fails")["serial_rerun"]["status"],
        "failed",
        "{tests}"
    );
    assert_eq!(
        by_name("fails")["serial_rerun"]["failures"][0],
        "broken_on_gpu"
    );
    assert!(by_name("passes").get("serial_rerun").is_none());
    let hangs = by_name("hangs");
    assert_eq!(hangs["status"], "timeout");
    assert_eq!(hangs["unfinished"], json!(["stuck", "after"]), "{hangs}");
    assert_eq!(hangs["serial_rerun"]["status"], "timeout", "{hangs}");
    assert_eq!(hangs["serial_rerun"]["cut_in"], "stuck", "{hangs}");
    assert_eq!(tests["passed"], 3);
    assert_eq!(tests["failed"], 1);
    assert_eq!(tests["binaries_failed"], 2);

    let benches = report["benches"].as_array().unwrap();
    assert_eq!(benches.len(), 5);
    for bench in benches {
        assert_eq!(bench["status"], "passed", "{bench}");
        assert_eq!(bench["report"]["steps_per_sec"], 125.5, "{bench}");
    }

    let job = &report["job"];
    assert_eq!(job["status"], "passed", "{job}");
    assert_eq!(job["steps"], "40");
    assert_eq!(job["wall_seconds"], 65);
    assert_eq!(job["psnr"], 19.29);
    assert_eq!(job["ssim"], 0.785);
    assert_eq!(job["stage_times"]["train"]["seconds"], 60);
    assert_eq!(job["objects"]["small"], 2);
    assert_eq!(job["metrics"]["held_out"]["views"], 3);
    assert!(job["last_progress"].as_str().unwrap().contains("40/40"));
    // The figures are printed too, and the step logs come back beside the report.
    assert!(stdout.contains("bench plain-1000px: passed"), "{stdout}");
    assert!(out.join("gpu_check_logs.tar.gz").is_file());
}
