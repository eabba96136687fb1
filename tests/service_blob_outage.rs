//! The service through a real outage of its object store: a test's own s3rver process is killed
//! with SIGKILL and started again on the same port and data (`common::s3rver`). An outage is not
//! a job's fault: a running job, or one whose scene is not yet on the worker, waits for the store
//! and finishes on its first attempt. An upload cut off by the outage leaves no scene and, once
//! the store is back, no files.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::archives::{colmap_zip, small_spec};
use common::handlers::{STEPS_KIND, StepsHandler};
use common::s3rver::OwnS3rver;
use common::{TestService, files_under, test_config};
use segsplat_scene::synthetic::SyntheticSpec;
use serde_json::json;

const WAIT: Duration = Duration::from_secs(40);
/// How long the store stays down: longer than a request's timeout (2 s) and than the three
/// attempts a job used to burn through.
const OUTAGE: Duration = Duration::from_millis(3500);

async fn service_on(server: &OwnS3rver, test: &str) -> (TestService, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.blobs = server.blobs(test);
    let handler = StepsHandler::default();
    (
        TestService::start(config, vec![Arc::new(handler)]).await,
        dir,
    )
}

async fn wait_for_end(client: &TestService, job_id: &str) -> serde_json::Value {
    let started = std::time::Instant::now();
    loop {
        let job = client.job(job_id).await;
        if ["succeeded", "failed", "cancelled"].contains(&job["state"].as_str().unwrap_or("")) {
            return job;
        }
        assert!(started.elapsed() < WAIT, "job {job_id} did not end: {job}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// With the server killed: waits out [`OUTAGE`], starts the server again and checks that the job
/// then succeeds on its first attempt. Returns the job as it was during the outage.
async fn end_outage_then_succeed(
    client: &TestService,
    server: &mut OwnS3rver,
    job_id: &str,
) -> serde_json::Value {
    tokio::time::sleep(OUTAGE).await;
    let during = client.job(job_id).await;
    tokio::task::block_in_place(|| server.restart());
    let finished = wait_for_end(client, job_id).await;
    assert_eq!(finished["state"], "succeeded", "{finished}");
    assert_eq!(
        finished["attempts"], 1,
        "an outage is not an attempt: {finished}"
    );
    during
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_running_job_outlives_a_blob_store_outage() {
    let test = "a_running_job_outlives_a_blob_store_outage";
    let Some(mut server) = OwnS3rver::start(test) else {
        return;
    };
    let (client, _dir) = service_on(&server, "running").await;
    let scene_id = client.upload_test_scene().await;
    // Checkpoints after every step, so the outage hits a checkpoint write.
    let job_id = client
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 80, "step_ms": 50}))
        .await;
    loop {
        let job = client.job(&job_id).await;
        if job["progress"]["step"].as_u64().unwrap_or(0) >= 10 {
            break;
        }
        assert_ne!(job["state"], "failed", "{job}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    tokio::task::block_in_place(|| server.kill());
    let during = end_outage_then_succeed(&client, &mut server, &job_id).await;
    assert_eq!(during["state"], "running", "{during}");
    client.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_waits_for_the_store_to_fill_its_scene_cache() {
    let test = "a_job_waits_for_the_store_to_fill_its_scene_cache";
    let Some(mut server) = OwnS3rver::start(test) else {
        return;
    };
    let (client, _dir) = service_on(&server, "cache").await;
    let scene_id = client.upload_test_scene().await;
    tokio::task::block_in_place(|| server.kill());
    // No worker has the scene yet: the claim has to fetch it from the dead store.
    let job_id = client
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 5}))
        .await;
    let during = end_outage_then_succeed(&client, &mut server, &job_id).await;
    assert_ne!(during["state"], "failed", "{during}");
    assert!(during["attempts"].as_u64() <= Some(1), "{during}");
    client.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_uploads_files_are_removed_once_the_store_is_back() {
    let test = "a_failed_uploads_files_are_removed_once_the_store_is_back";
    let Some(mut server) = OwnS3rver::start(test) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.blobs = server.blobs("upload");
    config.limits.max_upload_bytes = 64 << 20;
    let client = TestService::start(config, vec![]).await;
    // Many small frames: hundreds of PUTs, so the upload is still storing when the server dies.
    let archive = colmap_zip(SyntheticSpec {
        frame_count: 300,
        ..small_spec()
    });
    let upload = {
        let (http, url) = (client.client.clone(), client.url("/v1/scenes"));
        tokio::spawn(async move {
            let response = http
                .post(url)
                .header("content-type", "application/zip")
                .body(archive)
                .send()
                .await
                .unwrap();
            response.status().as_u16()
        })
    };
    let bucket = server.data_dir().to_path_buf();
    let stored_scene_files = || {
        files_under(&bucket)
            .into_iter()
            .filter(|path| path.to_string_lossy().contains("/scenes/"))
            .count()
    };
    let started = std::time::Instant::now();
    while stored_scene_files() == 0 {
        assert!(started.elapsed() < WAIT, "no scene file reached the bucket");
        assert!(
            !upload.is_finished(),
            "the upload ended before any file was stored"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    tokio::task::block_in_place(|| server.kill());
    let status = upload.await.unwrap();
    assert_eq!(status, 503, "an upload the store cut off");
    assert!(
        stored_scene_files() > 0,
        "files were left while the store was down"
    );
    tokio::time::sleep(Duration::from_secs(2)).await;
    tokio::task::block_in_place(|| server.restart());

    let (_, scenes) = client.get_json("/v1/scenes").await;
    assert_eq!(
        scenes["scenes"],
        json!([]),
        "no scene row without its blobs"
    );
    let started = std::time::Instant::now();
    while stored_scene_files() > 0 {
        assert!(
            started.elapsed() < WAIT,
            "the failed upload's files stay in the bucket: {:?}",
            files_under(&bucket)
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    client.shutdown().await;
}
