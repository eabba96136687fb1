//! The cluster's workers as an API process sees them: worker processes that share only the
//! database register each slot, heartbeat idle or busy (with the job), and mark themselves
//! stopped; a worker that goes silent without stopping (killed) counts as silent once a lease
//! passes. `GET /v1/workers`, `/readyz`'s cluster summary and the `segsplat_cluster_workers`
//! gauges all show it; a worker process answers probes and metrics on `workers.ops_addr`.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::handlers::{STEPS_KIND, StepsHandler};
use common::{TestService, test_config};
use segsplat_api::{RunningService, ServiceBuilder, ServiceMode};
use serde_json::{Value, json};

const WAIT: Duration = Duration::from_secs(20);

async fn start_worker(dir: &std::path::Path, instance: &str) -> RunningService {
    let mut config = test_config(dir);
    config.workers.cpu_slots = 1;
    config.workers.instance_id = Some(instance.to_string());
    ServiceBuilder::new(config)
        .mode(ServiceMode::WorkersOnly)
        .detect_gpus(false)
        .handler(Arc::new(StepsHandler::default()))
        .start()
        .await
        .unwrap()
}

/// Polls `GET /v1/workers` until `done` holds for it.
async fn wait_for_workers(api: &TestService, done: impl Fn(&Value) -> bool) -> Value {
    let started = std::time::Instant::now();
    loop {
        let (status, body) = api.get_json("/v1/workers").await;
        assert_eq!(status, 200, "{body}");
        if done(&body) {
            return body;
        }
        assert!(started.elapsed() < WAIT, "workers never got there: {body}");
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
}

fn worker<'a>(list: &'a Value, id: &str) -> &'a Value {
    list["workers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|worker| worker["id"] == id)
        .unwrap_or(&Value::Null)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn api_processes_see_every_workers_state() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.workers.cpu_slots = 0;
    let api = TestService::start(config, vec![Arc::new(StepsHandler::default())]).await;
    let box_a = start_worker(dir.path(), "box-a").await;
    let box_b = start_worker(dir.path(), "box-b").await;

    // A worker process serves the probes and its metrics on its own port, nothing else.
    let ops = format!("http://{}", box_a.http_addr().unwrap());
    for (path, status) in [("/healthz", 200), ("/metrics", 200), ("/v1/scenes", 404)] {
        let response = api.client.get(format!("{ops}{path}")).send().await.unwrap();
        assert_eq!(response.status().as_u16(), status, "{path}");
    }

    let list = wait_for_workers(&api, |list| list["idle"] == 2).await;
    for id in ["box-a/0", "box-b/0"] {
        let entry = worker(&list, id);
        assert_eq!(entry["alive"], true, "{list}");
        assert_eq!(entry["device"], "cpu", "{list}");
        assert_eq!(entry["kinds"], json!([STEPS_KIND]), "{list}");
    }

    let scene_id = api.upload_test_scene().await;
    let job_id = api
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 30, "step_ms": 50}))
        .await;
    let list = wait_for_workers(&api, |list| list["busy"] == 1).await;
    let busy: Vec<&Value> = list["workers"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|worker| worker["state"] == "busy")
        .collect();
    assert_eq!(busy[0]["job_id"], job_id.as_str(), "{list}");
    let (_, ready) = api.get_json("/readyz").await;
    assert_eq!(ready["cluster"]["busy"], 1, "{ready}");
    assert_eq!(ready["cluster"]["idle"], 1, "{ready}");
    api.wait_for_state(&job_id, "succeeded", WAIT).await;

    // A stopped worker says so; one that goes quiet without stopping is silent after a lease.
    box_b.shutdown().await;
    api.service
        .database()
        .register_worker("killed/0", "killed", "cpu", &[STEPS_KIND])
        .await
        .unwrap();
    let list = wait_for_workers(&api, |list| {
        list["silent"] == 1 && worker(list, "box-b/0")["state"] == "stopped"
    })
    .await;
    assert_eq!(worker(&list, "box-b/0")["alive"], false, "{list}");
    assert_eq!(worker(&list, "killed/0")["alive"], false, "{list}");
    assert_eq!(list["idle"], 1, "box-a is still there: {list}");
    let (_, metrics) = api.get_bytes("/metrics").await;
    let metrics = String::from_utf8(metrics).unwrap();
    assert!(
        metrics.contains("segsplat_cluster_workers{state=\"silent\"} 1"),
        "{metrics}"
    );
    box_a.shutdown().await;
    api.shutdown().await;
}
