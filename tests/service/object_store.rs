//! The service with its blobs in an S3-compatible bucket (a real server process started by
//! `scripts/test_servers.sh`): uploads land in the bucket and nowhere else, jobs checkpoint
//! there, a GPU job's worker fetches the scene from it and its trained files are served from it,
//! deleting a scene empties its prefixes; and with the bucket unreachable an upload is a 503 that
//! leaves nothing behind.

use std::sync::Arc;
use std::time::Duration;

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::SyntheticSpec;
use serde_json::json;

use crate::common::archives::{colmap_files, zip_of};
use crate::common::handlers::{STEPS_KIND, StepsHandler};
use crate::common::object_store::{s3_blobs, unreachable_s3_blobs};
use crate::common::{TestService, entries_in, files_under, test_config};

const WAIT: Duration = Duration::from_secs(30);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_and_checkpoints_live_in_the_bucket() {
    let Some(blobs) = s3_blobs("service") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.blobs = blobs;
    let handler = StepsHandler::default();
    let client = TestService::start(config, vec![Arc::new(handler.clone())]).await;
    let scene_id = client.upload_test_scene().await;
    let store = client.service.blobs();
    let scene_files = store
        .list_prefix(&format!("scenes/{scene_id}/files"))
        .unwrap();
    assert!(!scene_files.is_empty());
    assert!(
        files_under(&dir.path().join("blobs")).is_empty(),
        "nothing goes to the local blob directory"
    );

    let job_id = client
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 3}))
        .await;
    client.wait_for_state(&job_id, "succeeded", WAIT).await;
    // A succeeded job's checkpoints go from the bucket just after its state is recorded.
    let checkpoints = format!("jobs/{job_id}/checkpoints");
    let mut polls = 0;
    while !store.list_prefix(&checkpoints).unwrap().is_empty() {
        polls += 1;
        assert!(
            polls < 500,
            "a finished job's checkpoints stay in the bucket"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    let response = client
        .client
        .delete(client.url(&format!("/v1/scenes/{scene_id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 204);
    assert!(store.list_prefix("").unwrap().is_empty());
    client.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gpu_job_trains_from_the_bucket_and_its_result_is_served_from_it() {
    let Some(blobs) = s3_blobs("gpu") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let Some(client) =
        TestService::start_on_gpu(dir.path(), |config| config.blobs = blobs.clone()).await
    else {
        return;
    };
    let spec = SyntheticSpec {
        frame_count: 6,
        width: 40,
        height: 30,
        ..SyntheticSpec::default()
    };
    let archive = zip_of(&colmap_files(spec, ColmapEncoding::Binary));
    let (status, scene) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{scene}");
    let scene_id = scene["id"].as_str().unwrap();
    let job_id = client
        .create_job(
            scene_id,
            "reconstruct",
            json!({"steps": 30, "checkpoint_every": 10, "densify_from": 10,
                   "densify_interval": 10, "densify_until": 25}),
        )
        .await;
    client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(240))
        .await;
    let (status, ply) = client
        .get_bytes(&format!("/v1/scenes/{scene_id}/trained/scene.ply"))
        .await;
    assert_eq!(status, 200);
    let stored = client
        .service
        .blobs()
        .get_bytes(&format!("jobs/{job_id}/output/scene.ply"))
        .unwrap();
    assert_eq!(ply, stored);
    assert!(files_under(&dir.path().join("blobs")).is_empty());
    // The download was staged in the scratch folder to stream it, and is gone.
    assert!(
        files_under(&dir.path().join("tmp"))
            .iter()
            .all(|path| !path.to_string_lossy().starts_with("download-")),
        "{:?}",
        files_under(&dir.path().join("tmp"))
    );
    client.shutdown().await;
}

#[tokio::test]
async fn an_unreachable_bucket_is_a_503_that_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.blobs = unreachable_s3_blobs();
    let client = TestService::start(config, vec![]).await;
    let (status, ready) = client.get_json("/readyz").await;
    assert_eq!(status, 503, "{ready}");
    assert_eq!(ready["checks"]["blobs"]["ok"], false, "{ready}");
    assert!(
        ready["reasons"][0]
            .as_str()
            .is_some_and(|reason| reason.starts_with("blobs: the blob store is unavailable")),
        "{ready}"
    );
    let (status, body) = client
        .upload(
            crate::common::archives::colmap_zip(crate::common::archives::small_spec()),
            "application/zip",
        )
        .await;
    assert_eq!(status, 503, "{body}");
    assert_eq!(body["error"]["code"], "unavailable", "{body}");
    let (status, scenes) = client.get_json("/v1/scenes").await;
    assert_eq!(status, 200);
    assert_eq!(
        scenes["scenes"],
        json!([]),
        "no scene row without its blobs"
    );
    assert!(
        entries_in(&dir.path().join("tmp")).is_empty(),
        "the upload's temporary files are gone"
    );
    client.shutdown().await;
}
