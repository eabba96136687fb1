//! The durable job queue end to end, with a CPU-only test job kind: a job's lifecycle, progress
//! over SSE, validation and cancel. What survives a dead worker, a crash or a restart is in
//! [`crate::job_recovery`].

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use serde_json::json;

use crate::common::handlers::{STEPS_KIND, StepsHandler};
use crate::common::{TestService, test_config};

pub(crate) const WAIT: Duration = Duration::from_secs(15);

pub(crate) async fn start_with(
    dir: &std::path::Path,
    cpu_slots: u32,
    handler: &StepsHandler,
) -> TestService {
    let mut config = test_config(dir);
    config.workers.cpu_slots = cpu_slots;
    TestService::start(config, vec![Arc::new(handler.clone())]).await
}

/// SSE frames as (event name, data JSON).
pub(crate) fn parse_sse(text: &str) -> Vec<(String, serde_json::Value)> {
    text.split("\n\n")
        .filter_map(|frame| {
            let mut event = None;
            let mut data = None;
            for line in frame.lines() {
                if let Some(value) = line.strip_prefix("event:") {
                    event = Some(value.trim().to_string());
                } else if let Some(value) = line.strip_prefix("data:") {
                    data = serde_json::from_str(value.trim()).ok();
                }
            }
            Some((event?, data?))
        })
        .collect()
}

#[tokio::test]
async fn job_runs_to_success_and_sse_delivers_progress() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let service = start_with(dir.path(), 1, &handler).await;
    let scene_id = service.upload_test_scene().await;
    let job_id = service
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 5, "step_ms": 30}))
        .await;
    let response = service
        .client
        .get(service.url(&format!("/v1/jobs/{job_id}/events")))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 200);
    assert!(
        response.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/event-stream")
    );
    // The stream ends by itself after the final state.
    let text = tokio::time::timeout(WAIT, response.text())
        .await
        .unwrap()
        .unwrap();
    let events = parse_sse(&text);
    let states: Vec<&str> = events
        .iter()
        .filter(|(name, _)| name == "state")
        .map(|(_, data)| data["payload"]["state"].as_str().unwrap())
        .collect();
    assert_eq!(states, vec!["queued", "running", "succeeded"], "{text}");
    let progress: Vec<&serde_json::Value> = events
        .iter()
        .filter(|(name, _)| name == "progress")
        .map(|(_, data)| &data["payload"])
        .collect();
    assert_eq!(progress.len(), 5, "{text}");
    assert_eq!(progress[4]["step"], 5);
    assert_eq!(progress[4]["total_steps"], 5);
    assert_eq!(progress[4]["stage"], "count");
    assert!(progress[4]["metrics"]["loss"].as_f64().unwrap() > 0.0);
    assert!(
        progress[2]["eta_secs"].as_f64().unwrap() > 0.0,
        "{}",
        progress[2]
    );

    let job = service.job(&job_id).await;
    assert_eq!(job["state"], "succeeded");
    assert_eq!(job["attempts"], 1);
    assert_eq!(job["progress"]["step"], 5);
    assert_eq!(
        job["config"],
        json!({"steps": 5, "step_ms": 30, "fail_attempts": 0})
    );
    assert_eq!(handler.stats.runs.load(Ordering::SeqCst), 1);

    // Replay after the fact: same events, and resuming with Last-Event-ID skips the seen ones.
    let first_id = events[0].1["id"].as_i64().unwrap();
    let replay = service
        .client
        .get(service.url(&format!("/v1/jobs/{job_id}/events")))
        .header("last-event-id", first_id.to_string())
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert_eq!(parse_sse(&replay).len(), events.len() - 1);

    let (status, list) = service.get_json("/v1/jobs?state=succeeded").await;
    assert_eq!(status, 200);
    assert_eq!(list["jobs"].as_array().unwrap().len(), 1);
    let (status, list) = service.get_json("/v1/jobs?state=queued").await;
    assert_eq!(status, 200);
    assert!(list["jobs"].as_array().unwrap().is_empty());
    let (status, body) = service.get_json("/v1/jobs?state=sleeping").await;
    assert_eq!(status, 400, "{body}");
    service.shutdown().await;
}

#[tokio::test]
async fn job_requests_are_validated() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let service = start_with(dir.path(), 0, &handler).await;
    let scene_id = service.upload_test_scene().await;
    let path = format!("/v1/scenes/{scene_id}/jobs");
    let (status, body) = service.post_json(&path, json!({"kind": "teleport"})).await;
    assert_eq!(status, 422, "{body}");
    let message = body["error"]["message"].as_str().unwrap();
    assert!(
        message.contains("teleport") && message.contains(STEPS_KIND),
        "{message}"
    );
    let (status, body) = service
        .post_json(&path, json!({"kind": STEPS_KIND, "config": {"steps": 0}}))
        .await;
    assert_eq!(status, 422, "{body}");
    assert!(
        body["error"]["message"].as_str().unwrap().contains("steps"),
        "{body}"
    );
    let (status, _) = service
        .post_json("/v1/scenes/no-such-scene/jobs", json!({"kind": STEPS_KIND}))
        .await;
    assert_eq!(status, 404);
    let (status, _) = service.get_json("/v1/jobs/no-such-job").await;
    assert_eq!(status, 404);
    service.shutdown().await;
}

#[tokio::test]
async fn cancel_stops_queued_and_running_jobs_and_guards_scene_deletion() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let service = start_with(dir.path(), 1, &handler).await;
    let scene_id = service.upload_test_scene().await;
    let long = json!({"steps": 100000, "step_ms": 5});
    let running = service
        .create_job(&scene_id, STEPS_KIND, long.clone())
        .await;
    service.wait_for_state(&running, "running", WAIT).await;
    let queued = service.create_job(&scene_id, STEPS_KIND, long).await;
    assert_eq!(service.job(&queued).await["state"], "queued");

    // A scene with live jobs cannot be deleted.
    let response = service
        .client
        .delete(service.url(&format!("/v1/scenes/{scene_id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 409);

    let (status, body) = service
        .post_json(&format!("/v1/jobs/{queued}/cancel"), json!({}))
        .await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["state"], "cancelled");
    let (status, body) = service
        .post_json(&format!("/v1/jobs/{running}/cancel"), json!({}))
        .await;
    assert_eq!(status, 202, "{body}");
    assert_eq!(body["cancel_requested"], true);
    let job = service.wait_for_state(&running, "cancelled", WAIT).await;
    assert!(job["progress"]["step"].as_u64().unwrap() < 100000);
    let (status, _) = service
        .post_json(&format!("/v1/jobs/{running}/cancel"), json!({}))
        .await;
    assert_eq!(status, 409);
    // The cancelled queued job never ran.
    assert_eq!(handler.stats.runs.load(Ordering::SeqCst), 1);

    let response = service
        .client
        .delete(service.url(&format!("/v1/scenes/{scene_id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 204);
    let (status, _) = service.get_json(&format!("/v1/jobs/{running}")).await;
    assert_eq!(status, 404);
    service.shutdown().await;
}

#[tokio::test]
async fn a_cancel_stops_a_running_job_at_its_next_step_not_its_next_heartbeat() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    // Heartbeats 5 s apart: a cancel read only at the next heartbeat would let ~500 more
    // 10 ms steps run.
    config.jobs.heartbeat_secs = 5.0;
    config.jobs.lease_secs = 30.0;
    let handler = StepsHandler::new();
    let service = TestService::start(config, vec![Arc::new(handler)]).await;
    let scene_id = service.upload_test_scene().await;
    let job_id = service
        .create_job(
            &scene_id,
            STEPS_KIND,
            json!({"steps": 100000, "step_ms": 10}),
        )
        .await;
    let started = std::time::Instant::now();
    let at_cancel = loop {
        let job = service.job(&job_id).await;
        let step = job["progress"]["step"].as_u64().unwrap_or(0);
        if step >= 3 {
            break step;
        }
        assert!(started.elapsed() < WAIT, "no progress: {job}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    };
    let (status, body) = service
        .post_json(&format!("/v1/jobs/{job_id}/cancel"), json!({}))
        .await;
    assert_eq!(status, 202, "{body}");
    let job = service.wait_for_state(&job_id, "cancelled", WAIT).await;
    let last = job["progress"]["step"].as_u64().unwrap();
    assert!(
        last < at_cancel + 100,
        "{} steps ran after the cancel (from {at_cancel} to {last})",
        last - at_cancel
    );
    service.shutdown().await;
}

/// Starts workers only (no API) on `dir`, as `segsplat worker` does.

#[tokio::test]
async fn training_configs_beyond_the_service_limits_or_meaningless_get_422() {
    let dir = tempfile::tempdir().unwrap();
    // Validation only: no GPU worker runs these jobs.
    let service = TestService::start(
        test_config(dir.path()),
        vec![
            Arc::new(segsplat_service::job_kinds::ReconstructHandler),
            Arc::new(segsplat_service::job_kinds::SegmentThenSplatHandler),
        ],
    )
    .await;
    let scene_id = service.upload_test_scene().await;
    let path = format!("/v1/scenes/{scene_id}/jobs");
    let cases = [
        (
            "reconstruct",
            json!({"steps": 4_294_967_295u64}),
            "steps: 4294967295 is over this service's limit of 1000000 (jobs.max_steps)",
        ),
        (
            "segment_then_splat",
            json!({"steps": 100, "random_init_count": 20_000_000}),
            "random_init_count: 20000000 is over this service's limit of 10000000 \
             (jobs.max_gaussians)",
        ),
        (
            "reconstruct",
            json!({"learning_rates": {"opacity": -0.05}}),
            "learning_rates.opacity: must be a finite number >= 0",
        ),
        (
            "reconstruct",
            json!({"learning_rates": {"sh_rest_divisor": 0.0}}),
            "learning_rates.sh_rest_divisor",
        ),
    ];
    for (kind, config, message_part) in cases {
        let (status, body) = service
            .post_json(&path, json!({"kind": kind, "config": config}))
            .await;
        assert_eq!(status, 422, "{kind} {config}: {body}");
        let message = body["error"]["message"].as_str().unwrap();
        assert!(message.contains(message_part), "{message}");
    }
    let (_, jobs) = service.get_json("/v1/jobs").await;
    assert_eq!(jobs["jobs"].as_array().unwrap().len(), 0, "{jobs}");
    service.shutdown().await;
}
