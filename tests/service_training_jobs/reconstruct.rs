//! `reconstruct` jobs: artifacts in the blob store, the work each job reports on a shared adapter,
//! and a resume from a checkpoint written beside the step loop.

use std::time::Duration;

use segsplat_engine::labels::read_labels;
use segsplat_engine::ply::read_ply;

use crate::common::TestService;
use crate::support::{start_service, upload_small_scene};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reconstruct_job_trains_and_stores_artifacts() {
    let data = tempfile::tempdir().unwrap();
    let Some(client) = start_service(data.path()).await else {
        return;
    };
    let scene_id = &upload_small_scene(&client).await;

    let (status, body) = client
        .post_json(
            &format!("/v1/scenes/{scene_id}/jobs"),
            serde_json::json!({"kind": "reconstruct", "config": {"steps": -1}}),
        )
        .await;
    assert_eq!(status, 422, "a bad config is refused: {body}");

    let job_id = client
        .create_job(
            scene_id,
            "reconstruct",
            // One more SH band every 100 steps cannot happen in 60: the job says so.
            serde_json::json!({"steps": 60, "checkpoint_every": 25, "held_out_every": 20,
                               "densify_from": 20, "densify_interval": 20, "densify_until": 50,
                               "sh_degree_interval": 100}),
        )
        .await;
    let job = client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(240))
        .await;
    let (status, events) = client.get_bytes(&format!("/v1/jobs/{job_id}/events")).await;
    assert_eq!(status, 200);
    let events = String::from_utf8_lossy(&events);
    assert!(
        events.contains("event: warning") && events.contains("the SH degree stays 0"),
        "a stage the config makes impossible is a warning event: {events}"
    );
    assert_eq!(job["progress"]["stage"], "evaluate", "{job}");
    assert!(
        job["progress"]["metrics"]["psnr"].as_f64().unwrap() > 10.0,
        "{job}"
    );
    let worst = job["progress"]["metrics"]["worst_psnr"].as_f64().unwrap();
    assert!(
        worst > 5.0 && worst <= job["progress"]["metrics"]["psnr"].as_f64().unwrap(),
        "the worst held-out view is reported: {job}"
    );

    let blobs = client.service.blobs();
    let prefix = format!("jobs/{job_id}/output");
    let ply = blobs.get_bytes(&format!("{prefix}/scene.ply")).unwrap();
    let model = read_ply(ply.as_slice()).unwrap().model;
    assert!(!model.is_empty());
    let labels = blobs.get_bytes(&format!("{prefix}/labels.npy")).unwrap();
    assert_eq!(
        read_labels(labels.as_slice(), model.len()).unwrap().len(),
        model.len()
    );
    let metrics: serde_json::Value =
        serde_json::from_slice(&blobs.get_bytes(&format!("{prefix}/metrics.json")).unwrap())
            .unwrap();
    assert_eq!(metrics["steps"], 60);
    // The settings it ran with: the job's `settings` and metrics.json's agree (issue 41, item 1).
    assert!(
        metrics["settings"]["gaussian_budget"].as_u64().unwrap() > 0,
        "{metrics}"
    );
    assert_eq!(metrics["settings"]["train"]["steps"], 60, "{metrics}");
    let (status, finished) = client.get_json(&format!("/v1/jobs/{job_id}")).await;
    assert_eq!(status, 200);
    assert_eq!(finished["settings"], metrics["settings"], "{finished}");
    // The worst held-out view is named as the scene knows it (issue 41, item 3): every 8th
    // frame is held out, so its frame index is a multiple of 8 and its name the frame's.
    let held_out = &metrics["held_out"];
    let worst_frame = held_out["worst_frame_index"].as_u64().unwrap();
    assert_eq!(worst_frame % 8, 0, "{held_out}");
    assert_eq!(
        held_out["worst_frame_name"],
        format!("frame_{worst_frame:04}.png"),
        "{held_out}"
    );
    assert_eq!(
        job["progress"]["metrics"]["worst_frame_index"].as_f64(),
        Some(worst_frame as f64),
        "{job}"
    );
    // The host's side of the steps, and how busy the GPU was where the adapter times passes.
    let training = &metrics["training"];
    for field in [
        "bind_groups_created_per_step",
        "buffers_created_per_step",
        "compute_passes_per_step",
        "finish_ms_per_step",
    ] {
        assert!(training[field].is_number(), "{field} missing: {training}");
    }
    // Counted on the job's own thread (a context may be shared by several slots): a step's
    // dispatches and passes are there.
    assert!(
        training["dispatches_per_step"].as_f64().unwrap() >= 10.0
            && training["compute_passes_per_step"].as_f64().unwrap() >= 1.0,
        "{training}"
    );
    // The trainer fits the intersection capacity before its first step and keeps up after it:
    // no step of the job trained on a clamped render.
    assert_eq!(training["clamped_renders"], 0, "{training}");
    // wgpu's `finish` is part of the host's own time.
    let finish = training["finish_ms_per_step"].as_f64().unwrap();
    assert!(
        finish > 0.0 && finish <= training["host_ms_per_step"].as_f64().unwrap(),
        "{training}"
    );
    // Checkpoints are encoded and stored beside the step loop, which only takes the snapshot.
    assert!(
        training["checkpoint_write_seconds"].as_f64().unwrap() > 0.0,
        "{training}"
    );
    // Held-out quality every 20 steps between the checkpoints at 25 and 50 (the end's is the
    // job's own), against the training time before each.
    let curve = training["held_out_curve"]
        .as_array()
        .expect("held_out_curve");
    let steps: Vec<u64> = curve.iter().filter_map(|p| p["step"].as_u64()).collect();
    assert_eq!(steps, [20, 40], "{training}");
    assert!(
        curve.iter().all(
            |point| point["psnr"].as_f64() > Some(5.0) && point["gaussians"].as_u64() > Some(0)
        ),
        "{training}"
    );
    let seconds: Vec<f64> = curve
        .iter()
        .filter_map(|p| p["train_seconds"].as_f64())
        .collect();
    assert!(seconds[0] > 0.0 && seconds[1] > seconds[0], "{training}");
    let timestamps = segsplat_gpu::GpuContext::new_default()
        .map(|gpu| gpu.report.timestamp_queries)
        .unwrap_or(false);
    if timestamps {
        let busy = training["gpu_busy_fraction"].as_f64();
        assert!(
            busy.is_some_and(|busy| busy > 0.0 && busy <= 1.0),
            "gpu_busy_fraction: {training}"
        );
        // The sample behind it: steps with their shared passes timed, then with each dispatch.
        let timeline = &training["gpu_timeline"];
        assert_eq!(timeline["gpu_busy_fraction"].as_f64(), busy, "{training}");
        assert!(
            timeline["timeline_steps"]
                .as_u64()
                .is_some_and(|steps| steps
                    >= u64::from(segsplat_service::job_kinds::training::BUSY_SAMPLE_STEPS)),
            "{training}"
        );
        assert!(
            timeline["passes_per_step"]
                .as_f64()
                .is_some_and(|p| p >= 1.0)
                && timeline["pass_ms_per_step"]
                    .as_f64()
                    .is_some_and(|ms| ms > 0.0)
                && timeline["kernel_ms_per_step"]
                    .as_f64()
                    .is_some_and(|ms| ms > 0.0),
            "gpu_timeline: {training}"
        );
    }
    // A succeeded job's checkpoint goes (jobs.keep_final_checkpoint is off), just after the
    // state is recorded.
    let started = std::time::Instant::now();
    while !blobs
        .list_prefix(&format!("jobs/{job_id}/checkpoints/"))
        .unwrap()
        .is_empty()
    {
        assert!(started.elapsed().as_secs() < 10, "final checkpoint kept");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }

    // The convergence stop through the job (issue 38, item 2): a rule no fit can meet ends the
    // job at its first verdict. 7 training views: checks from step 3 (the last SH band) every
    // pass, so the window's start is there at step 10.
    let converging = client
        .create_job(
            scene_id,
            "reconstruct",
            serde_json::json!({"steps": 200, "checkpoint_every": 0, "densify_until": 0,
                               "sh_degree_interval": 1, "coarse_until": 0,
                               "stop_when_converged": {"min_gain_db": 1000.0, "window_passes": 1,
                                                       "check_every_passes": 1, "check_views": 2}}),
        )
        .await;
    let job = client
        .wait_for_state(&converging, "succeeded", Duration::from_secs(120))
        .await;
    let metrics: serde_json::Value = serde_json::from_slice(
        &blobs
            .get_bytes(&format!("jobs/{converging}/output/metrics.json"))
            .unwrap(),
    )
    .unwrap();
    let training = &metrics["training"];
    assert_eq!(training["converged_at"]["step"], 10, "{training}");
    assert_eq!(training["steps"], 10, "{training}");
    assert_eq!(
        training["fit_checks"].as_array().map(Vec::len),
        Some(2),
        "{training}"
    );
    assert_eq!(metrics["steps"], 10, "{metrics}");
    assert_eq!(
        job["settings"]["train"]["stop_when_converged"]["min_gain_db"], 1000.0,
        "{job}"
    );
    client.shutdown().await;
}

/// The dispatches a step the finished job `job_id` reports in its metrics.json.
fn dispatches_per_step(client: &TestService, job_id: &str) -> f64 {
    let bytes = client
        .service
        .blobs()
        .get_bytes(&format!("jobs/{job_id}/output/metrics.json"))
        .unwrap();
    let metrics: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    metrics["training"]["dispatches_per_step"]
        .as_f64()
        .unwrap_or_else(|| panic!("no dispatches_per_step: {metrics}"))
}

/// Two slots on one adapter (`workers.slots_per_adapter`) share its context: the kernels, the
/// uniform ring of kernel parameters, the profiler and the host-cost counters. Two jobs at once
/// both succeed, and each reports its own dispatches a step, as the same job alone does
/// (before stop 58 each counted the other's too).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_jobs_on_one_adapter_each_report_their_own_work() {
    let data = tempfile::tempdir().unwrap();
    let Some(client) = TestService::start_on_gpu(data.path(), |config| {
        config.workers.slots_per_adapter = 2;
    })
    .await
    else {
        return;
    };
    let scene_id = &upload_small_scene(&client).await;
    let config = serde_json::json!({"steps": 60, "checkpoint_every": 0, "seed": 3,
                                    "densify_from": 20, "densify_interval": 20,
                                    "densify_until": 50});
    let first = client
        .create_job(scene_id, "reconstruct", config.clone())
        .await;
    let second = client
        .create_job(scene_id, "reconstruct", config.clone())
        .await;
    let mut spans = Vec::new();
    for job_id in [&first, &second] {
        let job = client
            .wait_for_state(job_id, "succeeded", Duration::from_secs(300))
            .await;
        spans.push((
            job["started_at_ms"].as_i64(),
            job["finished_at_ms"].as_i64(),
        ));
    }
    let overlapped = matches!(
        spans[..],
        [(Some(a0), Some(a1)), (Some(b0), Some(b1))] if a0 < b1 && b0 < a1
    );
    println!("the two jobs ran at once: {overlapped} ({spans:?})");
    let alone = client.create_job(scene_id, "reconstruct", config).await;
    client
        .wait_for_state(&alone, "succeeded", Duration::from_secs(300))
        .await;
    let reference = dispatches_per_step(&client, &alone);
    for job_id in [&first, &second] {
        let shared = dispatches_per_step(&client, job_id);
        assert!(
            (shared / reference - 1.0).abs() < 0.1,
            "job {job_id} reports {shared} dispatches a step beside another job, {reference} alone"
        );
    }
}

/// A training job handed back at a shutdown after its first checkpoints resumes from the newest
/// on the next start and finishes. The checkpoints are written the job's way: the step loop
/// submits GPU copies of the trainer's state and the writer thread reads them back, encodes and
/// stores them (issue 38, item 4).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_resumes_from_a_checkpoint_read_back_beside_the_step_loop() {
    let data = tempfile::tempdir().unwrap();
    let Some(first) = start_service(data.path()).await else {
        return;
    };
    let scene_id = &upload_small_scene(&first).await;
    let steps = 1500;
    let job_id = first
        .create_job(
            scene_id,
            "reconstruct",
            serde_json::json!({"steps": steps, "checkpoint_every": 20, "densify_from": 20,
                               "densify_interval": 20, "densify_until": 200}),
        )
        .await;
    let checkpoints = format!("jobs/{job_id}/checkpoints/");
    let started = std::time::Instant::now();
    loop {
        let job = first.job(&job_id).await;
        let stored = !first
            .service
            .blobs()
            .list_prefix(&checkpoints)
            .unwrap()
            .is_empty();
        if stored && job["progress"]["step"].as_u64().unwrap_or(0) >= 50 {
            break;
        }
        assert_ne!(job["state"], "succeeded", "finished before the shutdown");
        assert!(started.elapsed().as_secs() < 240, "no checkpoint: {job}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    first.shutdown().await;

    let second = start_service(data.path())
        .await
        .expect("the GPU is still there");
    let job = second
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(300))
        .await;
    let (status, events) = second.get_bytes(&format!("/v1/jobs/{job_id}/events")).await;
    assert_eq!(status, 200);
    let resumed: Vec<u64> = String::from_utf8_lossy(&events)
        .lines()
        .filter_map(|line| line.strip_prefix("data:"))
        .filter_map(|data| serde_json::from_str::<serde_json::Value>(data.trim()).ok())
        .filter(|event| event["kind"] == "resumed")
        .filter_map(|event| event["payload"]["from_step"].as_u64())
        .collect();
    assert_eq!(resumed.len(), 1, "{job}");
    assert!(
        resumed[0] >= 20 && resumed[0].is_multiple_of(20),
        "resumed from step {}",
        resumed[0]
    );
    let metrics: serde_json::Value = serde_json::from_slice(
        &second
            .service
            .blobs()
            .get_bytes(&format!("jobs/{job_id}/output/metrics.json"))
            .unwrap(),
    )
    .unwrap();
    assert_eq!(
        metrics["training"]["steps"].as_u64(),
        Some(steps - resumed[0]),
        "the resumed attempt trains from its checkpoint: {metrics}"
    );
    assert!(
        metrics["held_out"]["psnr"].as_f64().unwrap() > 10.0,
        "{metrics}"
    );
    second.shutdown().await;
}
