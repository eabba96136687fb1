//! `?time=` where nothing moves: refused on a static scene, and the stored file for a dynamic
//! scene trained without a field.

use std::time::Duration;

use crate::common;
use crate::common::TestService;
use crate::support::{get_ok, upload_moving_spheres};

/// `?time=` on a static scene's trained files is refused, saying why, whether or not it is
/// trained (no GPU needed); without a time the files answer as before.
#[tokio::test]
async fn a_time_is_refused_for_a_static_scene() {
    let data = tempfile::tempdir().expect("tempdir");
    let client = TestService::start(common::test_config(data.path()), Vec::new()).await;
    let scene_id = client.upload_test_scene().await;
    for file in ["scene.ply", "scene.spz"] {
        let path = format!("/v1/scenes/{scene_id}/trained/{file}");
        let (status, body) = client.get_json(&format!("{path}?time=0.5")).await;
        assert_eq!(status, 400, "{body}");
        let message = body["error"]["message"].as_str().expect("message");
        assert!(
            message.contains(&scene_id) && message.contains("static"),
            "{message}"
        );
        let (status, body) = client.get_json(&path).await;
        assert_eq!(status, 409, "not trained yet, as before: {body}");
    }
    // What does not exist is a 404 (and an untrained scene a 409) whatever the time says;
    // only a file that exists is refused for having one.
    for (path, expected) in [
        ("/v1/scenes/no-such-scene/trained/scene.ply?time=0.5", 404),
        ("/v1/scenes/no-such-scene/trained/0?time=999999", 404),
        (
            &format!("/v1/scenes/{scene_id}/trained/nope.bin?time=0.5"),
            404,
        ),
        (
            &format!("/v1/scenes/{scene_id}/trained/labels.npy?time=0.5"),
            409,
        ),
    ] {
        let (status, body) = client.get_json(path).await;
        assert_eq!(status, expected, "{path}: {body}");
    }
    client.shutdown().await;
}

/// A dynamic scene trained without a field (`"deformation": null`) looks the same at every time:
/// `scene.ply?time=` is the stored file.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dynamic_scene_trained_static_serves_its_stored_scene_at_any_time() {
    let data = tempfile::tempdir().expect("tempdir");
    let Some(client) = TestService::start_on_gpu(data.path(), |_| {}).await else {
        return;
    };
    let scene_id = upload_moving_spheres(&client).await;
    let job_id = client
        .create_job(
            &scene_id,
            "reconstruct",
            serde_json::json!({"steps": 30, "checkpoint_every": 0, "deformation": null}),
        )
        .await;
    let job = client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(300))
        .await;
    // No sparse points and no `random_init_count`: the random start is sized from the scene
    // (its floor here, 5000, on this small capture) and the job's settings say so.
    assert_eq!(job["settings"]["train"]["random_init_count"], 5000, "{job}");
    let trained = format!("/v1/scenes/{scene_id}/trained");
    let (status, _) = client
        .get_bytes(&format!("{trained}/deformation.json"))
        .await;
    assert_eq!(status, 404, "trained without a field");
    let stored = get_ok(&client, &format!("{trained}/scene.ply")).await;
    assert_eq!(
        get_ok(&client, &format!("{trained}/scene.ply?time=0.5")).await,
        stored
    );
    client.shutdown().await;
}
