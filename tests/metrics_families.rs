//! `/metrics` by Prometheus' conventions, read with a Prometheus text-format parser the project
//! did not write: every family the service documents is present with `# HELP` and `# TYPE`,
//! counters end in `_total` and nothing else does, the query and mask-render histograms carry
//! the calling API and the outcome, process metrics and a build-info gauge are there, and
//! docs/service.md names every family.

mod common;

use std::collections::HashSet;
use std::sync::Arc;

use common::handlers::{STEPS_KIND, StepsHandler};
use common::{TestService, test_config};
use prometheus_parse::{Scrape, Value};
use segsplat_api::metrics::{FAMILIES, MetricType};
use serde_json::json;

#[tokio::test]
async fn every_documented_family_is_exported_with_help_and_type() {
    let dir = tempfile::tempdir().unwrap();
    let service =
        TestService::start(test_config(dir.path()), vec![Arc::new(StepsHandler::new())]).await;
    let scene_id = service.upload_test_scene().await;
    let job_id = service
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 2}))
        .await;
    service
        .wait_for_state(&job_id, "succeeded", std::time::Duration::from_secs(30))
        .await;
    // A query (no text encoder: 503) and a mask render (nothing trained: 409) both fail, and
    // both are timed, labelled as REST calls that ended in an error.
    let (status, _) = service
        .post_json(
            &format!("/v1/scenes/{scene_id}/query"),
            json!({"text": "red"}),
        )
        .await;
    assert_eq!(status, 503);
    let (status, _) = service
        .post_json(
            &format!("/v1/scenes/{scene_id}/masks"),
            json!({"view": {"frame_index": 0}, "objects": [{"level": "small", "object_id": 1}]}),
        )
        .await;
    assert_eq!(status, 409);
    let mut grpc = service.grpc().await;
    grpc.list_scenes(segsplat_api::proto::ListScenesRequest {})
        .await
        .unwrap();
    let missing = grpc
        .get_scene(segsplat_api::proto::GetSceneRequest {
            scene_id: "no-such-scene".to_string(),
        })
        .await
        .unwrap_err();
    assert_eq!(missing.code(), tonic::Code::NotFound);

    let response = service
        .client
        .get(service.url("/metrics"))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), 200);
    let text = response.text().await.unwrap();
    let scrape = Scrape::parse(text.lines().map(|line| Ok(line.to_string()))).unwrap();
    let documentation = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/service.md"),
    )
    .unwrap();

    for (name, kind, help) in FAMILIES {
        assert_eq!(
            scrape.docs.get(*name).map(String::as_str),
            Some(*help),
            "{name}: no # HELP"
        );
        let samples: Vec<_> = scrape
            .samples
            .iter()
            .filter(|sample| sample.metric == *name)
            .collect();
        assert!(!samples.is_empty(), "{name}: no samples in\n{text}");
        for sample in &samples {
            let typed = matches!(
                (kind, &sample.value),
                (MetricType::Counter, Value::Counter(_))
                    | (MetricType::Gauge, Value::Gauge(_))
                    | (MetricType::Histogram, Value::Histogram(_))
            );
            assert!(
                typed,
                "{name}: declared {kind:?}, exported {:?}",
                sample.value
            );
        }
        assert_eq!(
            name.ends_with("_total"),
            *kind == MetricType::Counter,
            "{name}: counters, and only counters, end in _total"
        );
        assert!(
            documentation.contains(name),
            "docs/service.md does not document {name}"
        );
    }
    let exported: HashSet<&str> = scrape
        .samples
        .iter()
        .map(|sample| sample.metric.as_str())
        .filter(|name| name.starts_with("segsplat_"))
        // A histogram's `_sum` and `_count` series belong to its family.
        .map(|name| {
            name.strip_suffix("_sum")
                .or_else(|| name.strip_suffix("_count"))
                .unwrap_or(name)
        })
        .collect();
    let listed: HashSet<&str> = FAMILIES.iter().map(|(name, _, _)| *name).collect();
    assert!(
        exported.is_subset(&listed),
        "exported but not listed in FAMILIES: {:?}",
        exported.difference(&listed).collect::<Vec<_>>()
    );

    let labelled = |metric: &str, api: &str, outcome: &str| {
        scrape.samples.iter().any(|sample| {
            sample.metric == metric
                && sample.labels.get("api") == Some(api)
                && sample.labels.get("outcome") == Some(outcome)
        })
    };
    assert!(
        labelled("segsplat_query_seconds", "rest", "error"),
        "{text}"
    );
    assert!(
        labelled("segsplat_mask_render_seconds", "rest", "error"),
        "{text}"
    );
    // gRPC codes by their canonical names (issue 41: the label was the number, "5").
    let grpc_code = |method: &str, code: &str| {
        scrape.samples.iter().any(|sample| {
            sample.metric == "segsplat_grpc_requests_total"
                && sample.labels.get("method") == Some(method)
                && sample.labels.get("code") == Some(code)
        })
    };
    assert!(
        grpc_code("/segsplat.v1.SceneQuery/ListScenes", "OK"),
        "{text}"
    );
    assert!(
        grpc_code("/segsplat.v1.SceneQuery/GetScene", "NOT_FOUND"),
        "{text}"
    );
    assert!(
        scrape
            .samples
            .iter()
            .all(|sample| sample.metric != "segsplat_grpc_requests_total"
                || sample
                    .labels
                    .get("code")
                    .is_some_and(|code| code.chars().all(|c| c.is_ascii_uppercase() || c == '_'))),
        "{text}"
    );
    // Job outcomes start at zero for each registered kind, not under a made-up kind "none".
    let outcomes: Vec<_> = scrape
        .samples
        .iter()
        .filter(|sample| sample.metric == "segsplat_job_outcomes_total")
        .collect();
    assert!(
        outcomes
            .iter()
            .all(|sample| sample.labels.get("kind") == Some(STEPS_KIND)),
        "{text}"
    );
    assert!(
        outcomes
            .iter()
            .any(|sample| sample.labels.get("outcome") == Some("failed")),
        "{text}"
    );
    let build = scrape
        .samples
        .iter()
        .find(|sample| sample.metric == "segsplat_build_info")
        .unwrap();
    assert_eq!(build.labels.get("version"), Some(env!("CARGO_PKG_VERSION")));
    assert!(
        build
            .labels
            .get("git_commit")
            .is_some_and(|commit| !commit.is_empty())
    );
    assert!(build.labels.get("adapter").is_some());
    for process in [
        "process_cpu_seconds_total",
        "process_resident_memory_bytes",
        "process_open_fds",
    ] {
        assert!(scrape.docs.contains_key(process), "{process}: no # HELP");
        assert!(
            scrape.samples.iter().any(|sample| sample.metric == process),
            "{process} missing"
        );
    }
    service.shutdown().await;
}
