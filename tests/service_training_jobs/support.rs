//! What the training-job tests share: a service on the GPU worker, a small scene, a short
//! `segment_then_splat` job and the progress it reported.

use std::time::Duration;

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::SyntheticSpec;

use crate::common::{TestService, archives};

pub(crate) async fn start_service(data: &std::path::Path) -> Option<TestService> {
    TestService::start_on_gpu(data, |_| {}).await
}

/// The steps of the job's progress events of `stage`, in order.
pub(crate) async fn stage_steps(client: &TestService, job_id: &str, stage: &str) -> Vec<u64> {
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
pub(crate) async fn run_short_segment_then_splat(
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
pub(crate) async fn upload_small_scene(client: &TestService) -> String {
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
