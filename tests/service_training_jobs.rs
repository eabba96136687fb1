//! The training job kinds end to end through the service on the GPU worker (lavapipe in CI):
//! upload, submit, progress over the job record, artifacts in the blob store, objects in the
//! database.

mod common;

use std::time::Duration;

use common::{TestService, archives};
use segsplat_engine::labels::read_labels;
use segsplat_engine::ply::read_ply;
use segsplat_scene::Level;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::SyntheticSpec;

async fn start_service(data: &std::path::Path) -> Option<TestService> {
    TestService::start_on_gpu(data, |_| {}).await
}

/// The steps of the job's progress events of `stage`, in order.
async fn stage_steps(client: &TestService, job_id: &str, stage: &str) -> Vec<u64> {
    let (status, events) = client.get_bytes(&format!("/v1/jobs/{job_id}/events")).await;
    assert_eq!(status, 200);
    String::from_utf8_lossy(&events)
        .lines()
        .filter_map(|line| line.strip_prefix("data:"))
        .filter_map(|data| serde_json::from_str::<serde_json::Value>(data.trim()).ok())
        .filter(|event| event["kind"] == "progress" && event["payload"]["stage"] == stage)
        .filter_map(|event| event["payload"]["step"].as_u64())
        .collect()
}

/// A 60-step `segment_then_splat` job on `scene_id`, awaited: (job id, finished job record).
async fn run_short_segment_then_splat(
    client: &TestService,
    scene_id: &str,
) -> (String, serde_json::Value) {
    let job_id = client
        .create_job(
            scene_id,
            "segment_then_splat",
            serde_json::json!({"steps": 60, "checkpoint_every": 30, "densify_from": 20,
                               "densify_interval": 20, "densify_until": 50,
                               "object_loss": {"objects_per_level": 1}}),
        )
        .await;
    let job = client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(300))
        .await;
    assert_eq!(job["progress"]["stage"], "persist", "{job}");
    (job_id, job)
}

/// Uploads the small synthetic COLMAP scene (9 views of 48 x 36) the reconstruct tests train on;
/// returns its id.
async fn upload_small_scene(client: &TestService) -> String {
    let spec = SyntheticSpec {
        frame_count: 9,
        width: 48,
        height: 36,
        ..SyntheticSpec::default()
    };
    let archive = archives::zip_of(&archives::colmap_files(spec, ColmapEncoding::Binary));
    let (status, scene) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{scene}");
    scene["id"].as_str().unwrap().to_string()
}

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

/// A training job handed back at a shutdown after its first checkpoints resumes from the newest
/// on the next start and finishes. The checkpoints are written the job's way: the step loop
/// submits GPU copies of the trainer's state and the writer thread reads them back, encodes and
/// stores them (issue 38, item 4).
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn segment_then_splat_job_stores_objects_at_three_levels() {
    let data = tempfile::tempdir().unwrap();
    let Some(client) = start_service(data.path()).await else {
        return;
    };
    let without_masks = SyntheticSpec {
        frame_count: 9,
        width: 48,
        height: 36,
        ..SyntheticSpec::default()
    };
    let archive = archives::zip_of(&archives::colmap_files(
        without_masks.clone(),
        ColmapEncoding::Binary,
    ));
    let (status, scene) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{scene}");
    let unmasked_id = scene["id"].as_str().unwrap();
    let job_id = client
        .create_job(
            unmasked_id,
            "segment_then_splat",
            serde_json::json!({"steps": 10, "masks": "user"}),
        )
        .await;
    let job = client
        .wait_for_state(&job_id, "failed", Duration::from_secs(120))
        .await;
    assert!(
        job["error"].as_str().unwrap_or_default().contains("masks"),
        "user masks asked of a scene without them fail with a reason: {job}"
    );
    // Without user masks or a SAM model, `auto` segments with the classical fallback.
    let job_id = client
        .create_job(
            unmasked_id,
            "segment_then_splat",
            serde_json::json!({"steps": 10, "checkpoint_every": 0}),
        )
        .await;
    let job = client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(240))
        .await;
    assert_eq!(job["progress"]["stage"], "persist", "{job}");
    // What the job was created with and what it ran with are told apart (issue 41, item 1):
    // `config` keeps `auto` and the default objects per level, `settings` the classical masks
    // and the one object per level of a scene this small, and a `settings` event carries them.
    assert_eq!(job["config"]["masks"], "auto", "{job}");
    assert_eq!(
        job["config"]["object_loss"]["objects_per_level"], 3,
        "{job}"
    );
    assert_eq!(job["settings"]["masks"], "classical", "{job}");
    assert_eq!(job["settings"]["steps"], 10, "{job}");
    assert_eq!(
        job["settings"]["object_loss"]["objects_per_level"], 1,
        "{job}"
    );
    let (status, events) = client.get_bytes(&format!("/v1/jobs/{job_id}/events")).await;
    assert_eq!(status, 200);
    let events = String::from_utf8_lossy(&events);
    assert!(events.contains("event: settings"), "{events}");
    // Where the time before the first step went (issue 38, item 5): the masks, their
    // association across views and the lost-track merge, then building the trainer.
    let (_, stored) = client
        .get_json(&format!("/v1/scenes/{unmasked_id}/trained/metrics.json"))
        .await;
    for field in ["masks_seconds", "association_seconds", "merge_seconds"] {
        let seconds = stored["segment"][field].as_f64();
        assert!(seconds.is_some_and(|s| s >= 0.0), "{field}: {stored}");
    }
    assert!(
        stored["training"]["setup_seconds"].as_f64() > Some(0.0),
        "{stored}"
    );
    // The trainer's kernels were compiled beside the masks (or by an earlier job on this
    // worker's context), so building the trainer compiled none and reused every one.
    let training = &stored["training"];
    assert!(training["kernels_compiled_ahead"].is_object(), "{stored}");
    assert_eq!(training["setup_kernels_compiled"], 0, "{stored}");
    assert!(
        training["setup_kernels_reused"].as_u64() > Some(0),
        "{stored}"
    );
    // What the partial-mask filter found (after step 8 of 10): pairs per level, the left-out
    // ones adding up to `skipped_pairs`, and how many of those render nothing.
    let filter = &stored["partial_filter"];
    assert_eq!(filter["after_step"], 8, "{stored}");
    let total = |field: &str| -> u64 {
        filter[field]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|count| count.as_u64())
            .sum()
    };
    assert!(total("pairs") > 0, "{stored}");
    assert_eq!(Some(total("skipped")), stored["skipped_pairs"].as_u64());
    assert!(filter["skipped_rendering_nothing"].as_u64() <= Some(total("skipped")));
    assert_eq!(filter["iou_quartiles"].as_array().map(Vec::len), Some(3));
    // Its pass's seconds, inside the stage's.
    let filter_seconds = training["partial_filter_seconds"].as_f64().unwrap_or(-1.0);
    assert!(
        filter_seconds > 0.0 && filter_seconds < training["seconds"].as_f64().unwrap_or(0.0),
        "{stored}"
    );
    // The segmentation stage reports each view as it is segmented, not only its start and end.
    let steps = stage_steps(&client, &job_id, "segment").await;
    let train_views = steps.last().copied().unwrap_or_default();
    assert!(train_views >= 7, "{steps:?}");
    let expected: Vec<u64> = (0..=train_views).chain([train_views]).collect();
    assert_eq!(steps, expected);
    // The training stage says it began before its first step, not at its first report (25
    // steps in, or at the end of a shorter run), so a client timing stages from their first
    // events times them right.
    let train_steps = stage_steps(&client, &job_id, "train").await;
    assert_eq!(train_steps.first(), Some(&0), "{train_steps:?}");
    assert_eq!(train_steps.last(), Some(&10), "{train_steps:?}");

    let with_masks = SyntheticSpec {
        with_masks: Some(Level::ALL.to_vec()),
        ..without_masks
    };
    let archive = archives::zip_of(&archives::colmap_files(with_masks, ColmapEncoding::Text));
    let (status, scene) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{scene}");
    let scene_id = scene["id"].as_str().unwrap();
    let (job_id, _) = run_short_segment_then_splat(&client, scene_id).await;

    let (status, objects) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects"))
        .await;
    assert_eq!(status, 200, "{objects}");
    let levels: Vec<&str> = objects["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["level"].as_str().unwrap())
        .collect();
    let count = |level: &str| levels.iter().filter(|l| **l == level).count();
    assert_eq!(
        (count("small"), count("middle"), count("large")),
        (3, 2, 1),
        "{objects}"
    );
    let (status, small) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects?level=small"))
        .await;
    assert_eq!(status, 200);
    assert_eq!(small["objects"].as_array().unwrap().len(), 3);
    let (status, _) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects?level=huge"))
        .await;
    assert_eq!(status, 400);
    let (status, body) = client
        .post_json(
            &format!("/v1/scenes/{scene_id}/query"),
            serde_json::json!({"text": "red"}),
        )
        .await;
    assert_eq!(status, 503, "no models configured: {body}");
    assert!(body.to_string().contains("no text encoder configured"));

    let blobs = client.service.blobs();
    let prefix = format!("jobs/{job_id}/output");
    for file in [
        "scene.ply",
        "labels.npy",
        "cameras.json",
        "objects.json",
        "skipped_pairs.json",
        "metrics.json",
    ] {
        assert!(blobs.exists(&format!("{prefix}/{file}")).unwrap(), "{file}");
    }
    client.shutdown().await;
}

/// The ONNX Runtime library can be loaded, or the test may be skipped (`SEGSPLAT_SKIP_ORT_TESTS=1`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn segment_then_splat_embeds_objects_and_answers_text_queries() {
    let data = tempfile::tempdir().unwrap();
    let models = common::tiny_models_dir();
    let Some(client) = TestService::start_with_tiny_models(data.path()).await else {
        return;
    };
    let archive = archives::queryable_scene_zip();
    let (status, scene) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{scene}");
    let scene_id = scene["id"].as_str().unwrap();
    let query_path = format!("/v1/scenes/{scene_id}/query");
    let query = |text: &str, granularity: &str| serde_json::json!({"text": text, "granularity": granularity, "top_k": 3});

    let (status, body) = client.post_json(&query_path, query("red", "small")).await;
    assert_eq!(status, 409, "nothing trained yet: {body}");
    let (status, body) = client.post_json(&query_path, query("red", "tiny")).await;
    assert_eq!(status, 400, "{body}");
    let (status, body) = client
        .post_json(&query_path, serde_json::json!({"text": "red", "top_k": 0}))
        .await;
    assert_eq!(status, 400, "{body}");
    let (status, body) = client
        .post_json("/v1/scenes/nope/query", query("red", "small"))
        .await;
    assert_eq!(status, 404, "{body}");

    let (_, job) = run_short_segment_then_splat(&client, scene_id).await;
    assert_eq!(
        job["progress"]["metrics"]["embeddings"], 6.0,
        "every object (3 small, 2 middle, 1 large) is embedded: {job}"
    );

    for (text, expected) in [("red", 1), ("a red mug", 1), ("green", 2), ("blue", 3)] {
        let (status, answer) = client.post_json(&query_path, query(text, "small")).await;
        assert_eq!(status, 200, "{answer}");
        println!("{text:?} (small): {answer}");
        assert_eq!(answer["matched"], true, "{text:?}: {answer}");
        let best = &answer["objects"][0];
        assert_eq!(best["level"], "small", "{text:?}: {answer}");
        assert_eq!(best["object_id"], expected, "{text:?}: {answer}");
        assert!(best["relevancy"].as_f64().unwrap() >= 0.55, "{answer}");
        assert!(best["bounds_max"][0].as_f64() >= best["bounds_min"][0].as_f64());
    }
    for granularity in ["small", "auto", "large"] {
        let (status, answer) = client
            .post_json(&query_path, query("a chair", granularity))
            .await;
        assert_eq!(status, 200, "{answer}");
        println!("\"a chair\" ({granularity}): {answer}");
        assert_eq!(answer["matched"], false, "{granularity}: {answer}");
        assert!(answer["objects"].as_array().unwrap().is_empty());
    }
    let (status, lenient) = client
        .post_json(
            &query_path,
            serde_json::json!({"text": "a chair", "granularity": "small", "threshold": 0.0}),
        )
        .await;
    assert_eq!(status, 200);
    println!("\"a chair\" (small, threshold 0): {lenient}");
    assert_eq!(
        lenient["matched"], true,
        "the threshold is the caller's: {lenient}"
    );

    // With a view, each match carries its masks.
    let (status, with_masks) = client
        .post_json(
            &query_path,
            serde_json::json!({"text": "green", "granularity": "small",
                               "view": {"frame_index": 0, "max_side": 48},
                               "mask_format": "png", "visible_masks": true}),
        )
        .await;
    assert_eq!(status, 200, "{with_masks}");
    let best = &with_masks["objects"][0];
    assert_eq!(best["object_id"], 2, "{with_masks}");
    assert_eq!(
        (
            &best["mask"]["format"],
            &best["mask"]["width"],
            &best["mask"]["height"]
        ),
        (
            &serde_json::json!("png"),
            &serde_json::json!(48),
            &serde_json::json!(36)
        ),
        "{with_masks}"
    );
    assert!(best["visible_mask"]["data"].is_string(), "{with_masks}");
    let (status, body) = client
        .post_json(
            &query_path,
            serde_json::json!({"text": "green", "granularity": "small",
                               "view": {"frame_index": 99}}),
        )
        .await;
    assert_eq!(status, 400, "{body}");

    stream_query_answers_each_pose(&client, scene_id).await;
    bad_views_are_refused_when_nothing_matches(&client, scene_id).await;
    client.shutdown().await;

    // `segsplat query` on the same data dir: the answer as JSON, masks as PNGs.
    let out = data.path().join("masks");
    let output = std::process::Command::new(common::segsplat_bin::segsplat_bin())
        .args([
            "query",
            scene_id,
            "blue",
            "--granularity",
            "small",
            "--frame",
            "0",
        ])
        .args(["--frame", "4", "--visible", "--data-dir"])
        .arg(data.path())
        .arg("--out")
        .arg(&out)
        .env("SEGSPLAT_MODELS__DIR", &models)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    let answer: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(answer["matched"], true, "{answer}");
    assert_eq!(answer["objects"][0]["object_id"], 3, "{answer}");
    let written = answer["objects"][0]["masks"].as_array().unwrap();
    assert_eq!(
        written.len(),
        4,
        "full and visible for two frames: {answer}"
    );
    let mask = image::open(out.join("0-small-3-frame4.png"))
        .unwrap()
        .into_luma8();
    assert_eq!(mask.dimensions(), (96, 72));
    assert!(mask.pixels().any(|pixel| pixel.0[0] == 255));
}

/// gRPC `StreamQuery`: the text is sent once, then poses; each reply echoes its sequence and
/// carries the mask for that pose; a bad pose ends the stream with INVALID_ARGUMENT.
async fn stream_query_answers_each_pose(client: &TestService, scene_id: &str) {
    use segsplat_api::proto;
    let (status, cameras) = client
        .get_json(&format!("/v1/scenes/{scene_id}/trained/cameras.json"))
        .await;
    assert_eq!(status, 200, "{cameras}");
    let pose_view = |index: usize| {
        let camera = &cameras[index];
        let rows: Vec<f64> = camera["camera_to_world"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|row| row.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
            .collect();
        proto::PoseView {
            pose: Some(proto::Pose {
                camera_to_world: rows,
            }),
            intrinsics: Some(proto::Intrinsics {
                fx: camera["fx"].as_f64().unwrap(),
                fy: camera["fy"].as_f64().unwrap(),
                cx: camera["cx"].as_f64().unwrap(),
                cy: camera["cy"].as_f64().unwrap(),
                width: camera["width"].as_u64().unwrap() as u32,
                height: camera["height"].as_u64().unwrap() as u32,
            }),
        }
    };
    let first = proto::StreamQueryRequest {
        scene_id: scene_id.to_string(),
        text: "blue".to_string(),
        granularity: proto::Granularity::Small as i32,
        top_k: 1,
        view: Some(pose_view(0)),
        time: None,
        mask_encoding: proto::MaskEncoding::CocoRle as i32,
        sequence: 10,
    };
    let second = proto::StreamQueryRequest {
        scene_id: String::new(),
        text: String::new(),
        view: Some(pose_view(3)),
        sequence: 11,
        ..first.clone()
    };
    let mut broken = second.clone();
    broken.sequence = 12;
    if let Some(pose) = broken.view.as_mut().and_then(|view| view.pose.as_mut()) {
        pose.camera_to_world.truncate(12);
    }
    let mut grpc = client.grpc().await;
    let mut replies = grpc
        .stream_query(futures::stream::iter(vec![first, second, broken]))
        .await
        .unwrap()
        .into_inner();
    for expected_sequence in [10, 11] {
        let reply = replies.message().await.unwrap().unwrap();
        assert_eq!(reply.sequence, expected_sequence);
        let response = reply.response.unwrap();
        assert!(!response.no_match, "{response:?}");
        let best = &response.matches[0];
        assert_eq!(best.object.as_ref().unwrap().object_id, 3, "{response:?}");
        let mask = best.mask.as_ref().unwrap();
        assert_eq!((mask.width, mask.height), (96, 72));
        assert!(mask.amodal && !mask.data.is_empty());
    }
    let error = replies.message().await.unwrap_err();
    assert_eq!(error.code(), tonic::Code::InvalidArgument, "{error}");
    assert!(error.message().contains("16 values"), "{error}");
}

/// A query whose text matches nothing still has its view checked (issue 41): a pose that is not
/// rigid, or a frame the scene lacks, is a bad request (REST 400, gRPC INVALID_ARGUMENT), not
/// "no match"; a good view with the same text is answered "no match".
async fn bad_views_are_refused_when_nothing_matches(client: &TestService, scene_id: &str) {
    use segsplat_api::proto;
    let query_path = format!("/v1/scenes/{scene_id}/query");
    let intrinsics = serde_json::json!({"fx": 80.0, "fy": 80.0, "cx": 48.0, "cy": 36.0, "width": 96, "height": 72});
    let scaled = serde_json::json!([[2.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1]]);
    let identity =
        serde_json::json!([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1]]);
    let asked = |view: serde_json::Value| serde_json::json!({"text": "a chair", "granularity": "small", "view": view});
    for (view, mentions) in [
        (
            serde_json::json!({"camera_to_world": scaled, "intrinsics": intrinsics}),
            "rigid",
        ),
        (serde_json::json!({"frame_index": 900}), "900"),
    ] {
        let (status, body) = client.post_json(&query_path, asked(view)).await;
        assert_eq!(status, 400, "{body}");
        assert!(
            body["error"]["message"]
                .as_str()
                .unwrap()
                .contains(mentions),
            "{body}"
        );
    }
    let good = serde_json::json!({"camera_to_world": identity, "intrinsics": intrinsics});
    let (status, body) = client.post_json(&query_path, asked(good)).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["matched"], false, "{body}");

    let mut grpc = client.grpc().await;
    let request = |rows: Vec<f64>| proto::QueryRequest {
        scene_id: scene_id.to_string(),
        text: "a chair".to_string(),
        granularity: proto::Granularity::Small as i32,
        top_k: 1,
        view: Some(proto::View {
            source: Some(proto::view::Source::Pose(proto::PoseView {
                pose: Some(proto::Pose {
                    camera_to_world: rows,
                }),
                intrinsics: Some(proto::Intrinsics {
                    fx: 80.0,
                    fy: 80.0,
                    cx: 48.0,
                    cy: 36.0,
                    width: 96,
                    height: 72,
                }),
            })),
            ..Default::default()
        }),
        mask_encoding: proto::MaskEncoding::Png as i32,
        ..Default::default()
    };
    let mut rows = vec![0.0; 16];
    for (index, value) in [(0, 2.0), (5, 1.0), (10, 1.0), (15, 1.0)] {
        rows[index] = value;
    }
    let refused = grpc.query(request(rows.clone())).await.unwrap_err();
    assert_eq!(refused.code(), tonic::Code::InvalidArgument, "{refused}");
    assert!(refused.message().contains("rigid"), "{refused}");
    rows[0] = 1.0;
    let answered = grpc.query(request(rows)).await.unwrap().into_inner();
    assert!(answered.no_match, "{answered:?}");
}

/// `masks: "propagated"`: SAM automatic masks on the first view carried through the others by
/// re-prompting, then trained, through the service. The tiny ONNX stand-in only follows a region
/// by the colour under its first point (it is not SAM), so this checks the plumbing: the job
/// runs without user masks or association, finds objects, and embeds only objects that kept
/// Gaussians. The automatic masks' settings come from the config (`automatic`), and a wrong one
/// is refused before anything is queued.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn segment_then_splat_with_propagated_masks() {
    let data = tempfile::tempdir().unwrap();
    let Some(client) = TestService::start_with_tiny_models(data.path()).await else {
        return;
    };
    let spec = SyntheticSpec {
        frame_count: 9,
        width: 96,
        height: 72,
        ..SyntheticSpec::default()
    };
    let archive = archives::zip_of(&archives::colmap_files(spec, ColmapEncoding::Text));
    let (status, scene) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{scene}");
    let scene_id = scene["id"].as_str().unwrap();
    for (automatic, named) in [
        (serde_json::json!({"points_per_side": 0}), "points_per_side"),
        (
            serde_json::json!({"mask_nms": {"min_score": 2.0}}),
            "mask_nms.min_score",
        ),
        (
            serde_json::json!({"points_per_sides": 8}),
            "points_per_sides",
        ),
    ] {
        let (status, body) = client
            .post_json(
                &format!("/v1/scenes/{scene_id}/jobs"),
                serde_json::json!({"kind": "segment_then_splat",
                                   "config": {"masks": "propagated", "automatic": automatic}}),
            )
            .await;
        assert_eq!(status, 422, "{body}");
        assert!(body.to_string().contains(named), "{named}: {body}");
    }
    let job_id = client
        .create_job(
            scene_id,
            "segment_then_splat",
            serde_json::json!({"steps": 40, "checkpoint_every": 0, "masks": "propagated",
                               "automatic": {"points_per_side": 16},
                               "object_loss": {"objects_per_level": 1}}),
        )
        .await;
    let job = client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(300))
        .await;
    let (status, objects) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects?level=small"))
        .await;
    assert_eq!(status, 200, "{objects}");
    assert!(
        objects["objects"].as_array().unwrap().len() >= 3,
        "{job} {objects}"
    );
    let metrics = &job["progress"]["metrics"];
    assert_eq!(
        metrics["embeddings"], metrics["objects"],
        "one embedding per object with Gaussians: {job}"
    );
    assert_eq!(job["config"]["automatic"]["points_per_side"], 16, "{job}");
    assert_eq!(
        job["config"]["automatic"]["points_per_batch"], 64,
        "the rest at the released settings: {job}"
    );
    let (_, stored) = client
        .get_json(&format!("/v1/scenes/{scene_id}/trained/metrics.json"))
        .await;
    assert_eq!(stored["segment"]["masks"], "propagated", "{stored}");
    assert_eq!(
        stored["segment"]["video_sequences"], 1.0,
        "a static scene is one sequence: {stored}"
    );
    client.shutdown().await;
}

/// A capture whose cameras have lens distortion says so where a user looks (issue 41, item 2):
/// the upload's reply and `GET /v1/scenes/{id}` list the lens, and a job on it records an
/// `undistorted` event.
#[tokio::test]
async fn a_distorted_capture_is_described_and_its_job_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let Some(client) = start_service(dir.path()).await else {
        return;
    };
    let spec = SyntheticSpec {
        frame_count: 4,
        width: 80,
        height: 60,
        camera_distance: 2.0,
        lens: Some(segsplat_scene::synthetic::SyntheticLens {
            model: segsplat_scene::colmap::CameraModel::OpenCv,
            distortion: vec![-0.35, 0.12, 0.003, -0.004],
        }),
        ..SyntheticSpec::default()
    };
    let archive = archives::zip_of(&archives::colmap_files(spec, ColmapEncoding::Text));
    let (status, uploaded) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{uploaded}");
    let scene_id = uploaded["id"].as_str().unwrap();
    let (status, described) = client.get_json(&format!("/v1/scenes/{scene_id}")).await;
    assert_eq!(status, 200, "{described}");
    for scene in [&uploaded, &described] {
        let lens = &scene["undistorted"][0];
        assert_eq!(lens["model"], "OPENCV", "{scene}");
        assert_eq!(lens["frame_count"], 4, "{scene}");
    }
    let job_id = client
        .create_job(scene_id, "reconstruct", serde_json::json!({"steps": 5}))
        .await;
    client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(240))
        .await;
    let (status, events) = client.get_bytes(&format!("/v1/jobs/{job_id}/events")).await;
    assert_eq!(status, 200);
    let events = String::from_utf8_lossy(&events);
    assert!(events.contains("event: undistorted"), "{events}");
    assert!(events.contains("OPENCV"), "{events}");
    client.shutdown().await;
}
