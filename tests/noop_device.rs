//! wgpu's no-op device (`GpuContext::new_noop`, `segsplat bench --noop-device`): every kernel
//! compiled and every dispatch recorded, validated and submitted, none run. It needs no adapter,
//! so these run everywhere CI does, and it is shaped like a GPU, so the kernels and sizes a GPU
//! gets are the ones checked (a software adapter gets its own).

mod gpu_support;

use gpu_support::segsplat;

fn synthetic_scene(dir: &tempfile::TempDir) -> String {
    let scene = dir.path().join("scene");
    let scene = scene.to_str().expect("utf-8 path").to_string();
    let written = segsplat(&[
        "synthetic-scene",
        &scene,
        "--frames",
        "6",
        "--width",
        "48",
        "--height",
        "32",
    ]);
    assert!(written.status.success(), "{written:?}");
    scene
}

fn bench_on_noop(scene: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "bench",
        scene,
        "--noop-device",
        "--max-resolution",
        "48",
        "--timing-repeats",
        "1",
        "--json",
    ];
    args.extend_from_slice(extra);
    let output = segsplat(&args);
    assert!(output.status.success(), "{output:?}");
    serde_json::from_slice(&output.stdout).expect("bench prints one JSON object")
}

/// The host's side of a step, with no device work in it: its dispatches share passes, and the
/// time in wgpu's `finish` is part of the host's own time.
#[test]
fn bench_on_the_noop_device_reports_the_hosts_side_of_a_step() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scene = synthetic_scene(&dir);
    let report = bench_on_noop(&scene, &["--steps", "30"]);
    assert_eq!(report["adapter"], "noop wgpu backend", "{report}");
    assert_eq!(report["steps"], 30, "{report}");
    // Densification is off on the no-op device: it would prune the all-zero model.
    assert_eq!(
        report["gaussians_end"], report["gaussians_start"],
        "{report}"
    );
    let dispatches = report["dispatches_per_step"].as_f64().expect("dispatches");
    assert!(dispatches >= 10.0, "{report}");
    let host = &report["host"];
    let passes = host["compute_passes_per_step"].as_f64().expect("passes");
    assert!(passes >= 1.0 && passes < dispatches / 2.0, "{report}");
    let own = host["host_ms_per_step"].as_f64().expect("host ms");
    let finish = host["finish_ms_per_step"].as_f64().expect("finish ms");
    assert!(finish > 0.0 && finish <= own, "{report}");
    assert_eq!(host["buffers_created_per_step"], 0.0, "{report}");
}

/// The deformation field a GPU gets (8 x 256, the tiled GEMM), not a software adapter's
/// (4 x 64, rows or subgroup broadcast): the no-op device validates the GPU's kernels here.
#[test]
fn the_noop_device_gets_a_gpus_kernels() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scene = synthetic_scene(&dir);
    let report = bench_on_noop(&scene, &["--steps", "4", "--deformation"]);
    let deformation = &report["deformation"];
    assert_eq!(deformation["field"]["depth"], 8, "{report}");
    assert_eq!(deformation["field"]["width"], 256, "{report}");
    assert_eq!(deformation["gemm_kernel"], "tiled", "{report}");
}
