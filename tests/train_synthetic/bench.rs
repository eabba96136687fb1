//! `segsplat bench` through the CLI: from a trained PLY, and timing the object loss against plain
//! steps in one invocation.

use crate::gpu_support::{new_gpu_context, segsplat, write_synthetic_scene};

/// `segsplat train` writes a trained scene and `segsplat bench --init-ply` times steps starting
/// from its Gaussians (the trained-density benchmark of docs/benchmarks.md), and
/// `--profile-kernels` breaks a step's GPU time down by kernel.
#[test]
fn bench_starts_from_a_trained_ply() {
    if new_gpu_context().is_none() {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let scene = write_synthetic_scene(
        dir.path(),
        "scene",
        &["--frames", "6", "--width", "32", "--height", "24"],
    );
    let scene = scene.as_str();
    let out = dir.path().join("trained");
    let out = out.to_str().expect("utf-8 path");
    let trained = segsplat(&["train", scene, "--steps", "5", "--out", out]);
    assert!(trained.status.success(), "{trained:?}");
    let ply = format!("{out}/scene.ply");
    let count = segsplat_engine::ply::read_ply_file(std::path::Path::new(&ply))
        .expect("trained ply")
        .model
        .len();
    let output = segsplat(&[
        "bench",
        scene,
        "--steps",
        "2",
        "--max-resolution",
        "32",
        "--no-densify",
        "--init-ply",
        &ply,
        "--timing-repeats",
        "1",
        "--profile-kernels",
        "2",
        "--busy-steps",
        "20",
        "--json",
    ]);
    assert!(output.status.success(), "{output:?}");
    let report: serde_json::Value =
        serde_json::from_slice(&output.stdout).expect("bench prints one JSON object");
    assert_eq!(report["gaussians_start"], count, "{report}");
    // The kernel profile times every pass of the two profiled steps, by kernel.
    let profile = &report["kernel_profile"];
    assert_eq!(profile["steps"], 2, "{report}");
    let kernels = profile["kernels"].as_array().expect("kernels by time");
    let timed = |name: &str| {
        kernels
            .iter()
            .find(|k| k["kernel"].as_str().is_some_and(|k| k.starts_with(name)))
            .and_then(|k| k["ms"].as_f64())
    };
    for kernel in [
        "project_forward",
        "rasterize_forward",
        "rasterize_backward",
        "adam_step",
    ] {
        assert!(
            timed(kernel).is_some_and(|ms| ms >= 0.0),
            "{kernel}: {report}"
        );
    }
    let total: f64 = kernels.iter().filter_map(|k| k["ms"].as_f64()).sum();
    let reported = profile["gpu_ms_per_step"].as_f64().expect("gpu ms");
    assert!(
        (total - reported).abs() < 1e-6 * reported.max(1.0),
        "{report}"
    );
    // Before the kernels, a job's sample of steps ran with only their shared passes timed: the
    // GPU's timeline over them, whose filled share is the busy fraction.
    let timeline = &profile["timeline"];
    assert_eq!(timeline["timeline_steps"], 20, "{report}");
    assert_eq!(timeline["kernel_steps"], 2, "{report}");
    let field = |name: &str| timeline[name].as_f64().expect(name);
    // Shared passes: a few a step, far fewer than the dispatches.
    assert!((1.0..20.0).contains(&field("passes_per_step")), "{report}");
    assert!(field("pass_ms_per_step") > 0.0, "{report}");
    let busy = field("gpu_busy_fraction");
    assert!(busy > 0.0 && busy <= 1.0, "{report}");
    assert_eq!(
        profile["gpu_busy_fraction"].as_f64(),
        Some(busy),
        "{report}"
    );
    assert!(
        field("idle_ms_per_step") >= 0.0 && field("longest_gap_ms") >= 0.0,
        "{report}"
    );
    let missing = segsplat(&[
        "bench",
        scene,
        "--steps",
        "1",
        "--init-ply",
        "/nonexistent.ply",
    ]);
    assert!(!missing.status.success());
    assert!(
        String::from_utf8_lossy(&missing.stderr).contains("/nonexistent.ply"),
        "{missing:?}"
    );
}

/// `bench --object-loss` times the object-loss run and a plain run on the same Gaussians in
/// turns (so a change in the machine's speed falls on both) and reports their step-time ratio,
/// with the partial-mask filter timed apart.
#[test]
fn bench_times_the_object_loss_against_plain_steps_in_one_invocation() {
    if new_gpu_context().is_none() {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let scene = write_synthetic_scene(
        dir.path(),
        "scene",
        &["--frames", "8", "--width", "40", "--height", "30"],
    );
    let scene = scene.as_str();
    // 60 steps: two whole turns of 25 and a short one on each side.
    let output = segsplat(&[
        "bench",
        scene,
        "--steps",
        "60",
        "--max-resolution",
        "40",
        "--no-densify",
        "--object-loss",
        "--objects-per-level",
        "1",
        "--timing-repeats",
        "1",
        "--json",
    ]);
    assert!(output.status.success(), "{output:?}");
    let report: serde_json::Value =
        serde_json::from_slice(&output.stdout).expect("bench prints one JSON object");
    assert_eq!(report["steps"], 60, "{report}");
    assert_eq!(report["object_loss"]["masks"], "user", "{report}");
    let plain = &report["plain_baseline"];
    assert_eq!(
        plain["gaussians_start"], report["gaussians_start"],
        "{report}"
    );
    let number = |value: &serde_json::Value| value.as_f64().unwrap_or(f64::NAN);
    assert!(number(&plain["steps_per_sec"]) > 0.0, "{report}");
    assert!(number(&report["steps_per_sec"]) > 0.0, "{report}");
    let ratio = number(&plain["step_time_ratio"]);
    let with_filter = number(&plain["step_time_ratio_with_filter"]);
    assert!(ratio > 0.0 && ratio <= with_filter, "{report}");
    assert!(number(&plain["partial_filter_seconds"]) > 0.0, "{report}");
    assert!(
        plain["partial_filter"]["iou_quartiles"].is_array(),
        "{report}"
    );
    // The object slots add their renders' and their batched loss's dispatches to a step.
    assert!(
        number(&report["dispatches_per_step"]) > number(&plain["dispatches_per_step"]),
        "{report}"
    );
}
