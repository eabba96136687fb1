//! Tenants (issue 19 item 14): every REST route in the served OpenAPI document and every gRPC
//! method in the service descriptor, called with tenant beta's token on tenant alpha's scene
//! and job, answers 404 / NOT_FOUND or a list without them; alpha and an admin do see them.
//! The routes and methods are iterated from the documents, so a new one without a case here
//! fails the test instead of going unchecked.

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use prost::Message;
use segsplat_api::proto;
use segsplat_api::proto::scene_query_client::SceneQueryClient;
use segsplat_scene::Level;
use segsplat_service::config::TenantToken;
use segsplat_service::store::objects::ObjectRecord;
use serde_json::{Value, json};

use crate::common::handlers::{STEPS_KIND, StepsHandler};
use crate::common::{TestService, archives, test_config};

const ALPHA: &str = "alpha-token";
const BETA: &str = "beta-token";
const ADMIN: &str = "admin-token";
/// A plain `auth.tokens` entry: the default tenant.
const LEGACY: &str = "legacy-token";
const OBJECT_ID: u32 = 3;

/// Paths that hold no tenant's data (probes, the API description).
const OPEN_PATHS: [&str; 4] = ["/healthz", "/readyz", "/metrics", "/v1/openapi.json"];
/// Paths about the whole cluster (workers run every tenant's jobs): admin tokens only.
const ADMIN_PATHS: [&str; 1] = ["/v1/workers"];

fn tenant_token(token: &str, tenant: Option<&str>, admin: bool) -> TenantToken {
    TenantToken {
        token: token.to_string(),
        tenant: tenant.map(str::to_string),
        admin,
    }
}

async fn start() -> (tempfile::TempDir, TestService) {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.auth.tokens = vec![LEGACY.to_string()];
    config.auth.token = vec![
        tenant_token(ALPHA, Some("alpha"), false),
        tenant_token(BETA, Some("beta"), false),
        tenant_token(ADMIN, Some("ops"), true),
    ];
    let service = TestService::start(config, vec![Arc::new(StepsHandler::new())]).await;
    (dir, service)
}

/// What tenant alpha owns: a scene with a finished job and one stored object.
struct Owned {
    scene: String,
    job: String,
}

async fn send(
    service: &TestService,
    token: &str,
    method: &str,
    path: &str,
    body: Option<Body>,
) -> (u16, String) {
    let method = reqwest::Method::from_bytes(method.to_uppercase().as_bytes()).unwrap();
    let mut request = service
        .client
        .request(method, service.url(path))
        .bearer_auth(token);
    match body {
        Some(Body::Json(value)) => request = request.json(&value),
        Some(Body::Archive(bytes)) => {
            request = request
                .header("content-type", "application/zip")
                .body(bytes)
        }
        None => {}
    }
    // SSE of a finished job ends by itself; the timeout guards a stream that would not.
    let response = tokio::time::timeout(Duration::from_secs(20), request.send())
        .await
        .expect("request timed out")
        .unwrap();
    let status = response.status().as_u16();
    let text = tokio::time::timeout(Duration::from_secs(20), response.text())
        .await
        .expect("body timed out")
        .unwrap_or_default();
    (status, text)
}

enum Body {
    Json(Value),
    Archive(Vec<u8>),
}

async fn upload(service: &TestService, token: &str) -> String {
    let archive = archives::colmap_zip(archives::small_spec());
    let (status, body) = send(
        service,
        token,
        "post",
        "/v1/scenes",
        Some(Body::Archive(archive)),
    )
    .await;
    assert_eq!(status, 201, "{body}");
    let body: Value = serde_json::from_str(&body).unwrap();
    body["id"].as_str().unwrap().to_string()
}

async fn owned_by(service: &TestService, token: &str) -> Owned {
    let scene = upload(service, token).await;
    let (status, body) = send(
        service,
        token,
        "post",
        &format!("/v1/scenes/{scene}/jobs"),
        Some(Body::Json(
            json!({"kind": STEPS_KIND, "config": {"steps": 1}}),
        )),
    )
    .await;
    assert_eq!(status, 201, "{body}");
    let job: Value = serde_json::from_str(&body).unwrap();
    let job = job["id"].as_str().unwrap().to_string();
    wait_until_finished(service, token, &job).await;
    let object = ObjectRecord {
        scene_id: scene.clone(),
        level: Level::Small,
        object_id: OBJECT_ID,
        gaussian_count: 10,
        centroid: [0.0; 3],
        bounds_min: [-1.0; 3],
        bounds_max: [1.0; 3],
        mean_color: [0.5; 3],
    };
    service
        .service
        .database()
        .replace_objects(&scene, &[object], &[])
        .await
        .unwrap();
    Owned { scene, job }
}

async fn wait_until_finished(service: &TestService, token: &str, job: &str) {
    for _ in 0..400 {
        let (_, body) = send(service, token, "get", &format!("/v1/jobs/{job}"), None).await;
        let state = serde_json::from_str::<Value>(&body).unwrap()["state"].clone();
        if ["succeeded", "failed", "cancelled"].contains(&state.as_str().unwrap_or("")) {
            return;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    panic!("job {job} did not finish");
}

/// Waits until no job of any tenant is queued or running.
async fn wait_for_idle(service: &TestService) {
    for _ in 0..400 {
        let (_, body) = send(service, ADMIN, "get", "/v1/jobs", None).await;
        if !body.contains("\"queued\"") && !body.contains("\"running\"") {
            return;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    panic!("jobs did not finish");
}

/// The request path with alpha's ids filled in; panics on a parameter this test does not know
/// (a new route shape: teach the test what to put there).
fn fill_path(template: &str, owned: &Owned) -> String {
    let id = if template.starts_with("/v1/jobs/") {
        &owned.job
    } else {
        &owned.scene
    };
    let mut path = template.to_string();
    for (name, value) in [
        ("{id}", id.to_string()),
        ("{level}", "small".to_string()),
        ("{object_id}", OBJECT_ID.to_string()),
        ("{file}", "scene.ply".to_string()),
    ] {
        path = path.replace(name, &value);
    }
    assert!(
        !path.contains('{'),
        "{template}: a path parameter this test does not know how to fill"
    );
    path
}

/// Query strings and bodies the routes need to get past their own validation to the tenant
/// check; panics for a route with a body that has no case here.
fn request_for(method: &str, template: &str, operation: &Value) -> (String, Option<Body>) {
    let query = match template {
        "/v1/scenes/{id}/objects/{level}/{object_id}/mask.png" => "?frame_index=0",
        _ => "",
    };
    let body = match (method, template) {
        ("post", "/v1/scenes") => Some(Body::Archive(archives::colmap_zip(archives::small_spec()))),
        ("post", "/v1/scenes/{id}/jobs") => Some(Body::Json(
            json!({"kind": STEPS_KIND, "config": {"steps": 1}}),
        )),
        ("post", "/v1/scenes/{id}/query") => Some(Body::Json(json!({"text": "mug"}))),
        ("post", "/v1/scenes/{id}/masks") => Some(Body::Json(json!({
            "objects": [{"level": "small", "object_id": OBJECT_ID}],
            "view": {"frame_index": 0},
        }))),
        _ => {
            assert!(
                operation.get("requestBody").is_none(),
                "{method} {template} takes a body this test does not know"
            );
            None
        }
    };
    (query.to_string(), body)
}

/// Whether a response carries any of alpha's ids (a 404 may echo the id the client sent).
fn leaks(status: u16, body: &str, owned: &Owned) -> bool {
    status != 404 && (body.contains(&owned.scene) || body.contains(&owned.job))
}

#[tokio::test]
async fn every_rest_route_keeps_tenants_apart() {
    let (_dir, service) = start().await;
    let alpha = owned_by(&service, ALPHA).await;
    let beta = owned_by(&service, BETA).await;

    let (status, document) = send(&service, ALPHA, "get", "/v1/openapi.json", None).await;
    assert_eq!(status, 200);
    let document: Value = serde_json::from_str(&document).unwrap();
    let mut operations = Vec::new();
    for (template, item) in document["paths"].as_object().unwrap() {
        for (method, operation) in item.as_object().unwrap() {
            operations.push((method.clone(), template.clone(), operation.clone()));
        }
    }
    // Deletes last: they remove what the other calls look at.
    operations.sort_by_key(|(method, _, _)| method == "delete");
    assert!(operations.len() >= 15, "{} operations", operations.len());

    let mut checked = BTreeSet::new();
    for (method, template, operation) in &operations {
        let path = fill_path(template, &alpha);
        let (query, _) = request_for(method, template, operation);
        let url = format!("{path}{query}");
        let call = |token| {
            let (_, body) = request_for(method, template, operation);
            send(&service, token, method, &url, body)
        };
        let (status, body) = call(BETA).await;
        assert_ne!(status, 401, "{method} {template}: beta's token refused");
        assert!(
            !leaks(status, &body, &alpha),
            "{method} {template}: beta got alpha's data ({status}): {body}"
        );
        let is_open = OPEN_PATHS.contains(&template.as_str());
        if template.contains('{') {
            assert_eq!(
                status, 404,
                "{method} {template}: beta got {status}: {body}"
            );
        }
        if is_open || method == "post" && template == "/v1/scenes" {
            checked.insert(format!("{method} {template}"));
            continue;
        }
        if ADMIN_PATHS.contains(&template.as_str()) {
            assert_eq!(
                status, 403,
                "{method} {template}: beta got {status}: {body}"
            );
            let (status, body) = call(ALPHA).await;
            assert_eq!(
                status, 403,
                "{method} {template}: alpha got {status}: {body}"
            );
            let (status, body) = call(ADMIN).await;
            assert_eq!(
                status, 200,
                "{method} {template}: admin got {status}: {body}"
            );
            checked.insert(format!("{method} {template}"));
            continue;
        }
        if method == "delete" {
            // Beta's delete did nothing: alpha still has the scene; then the admin may (once
            // the jobs queued above are done: a scene with active jobs is not deleted).
            wait_for_idle(&service).await;
            let (status, _) = send(&service, ALPHA, "get", &path, None).await;
            assert_eq!(
                status, 200,
                "{method} {template}: beta's call removed alpha's scene"
            );
            let (status, body) = call(ADMIN).await;
            assert_eq!(
                status, 204,
                "{method} {template}: admin got {status}: {body}"
            );
            checked.insert(format!("{method} {template}"));
            continue;
        }
        for (who, token) in [("alpha", ALPHA), ("admin", ADMIN)] {
            let (status, body) = call(token).await;
            assert!(
                ![401, 404].contains(&status),
                "{method} {template}: {who} got {status}: {body}"
            );
            if !template.contains('{') {
                // A list: alpha's things are in it for alpha and the admin.
                assert!(
                    body.contains(&alpha.scene),
                    "{method} {template}: {who}'s list lacks alpha's scene: {body}"
                );
            }
        }
        if !template.contains('{') {
            // Beta's own things are in its list: filtered, not emptied.
            let (_, body) = call(BETA).await;
            assert!(body.contains(&beta.scene), "{method} {template}: {body}");
        }
        checked.insert(format!("{method} {template}"));
    }
    assert_eq!(checked.len(), operations.len());

    // A plain `auth.tokens` token is the default tenant: it sees neither alpha nor beta.
    let (status, body) = send(&service, LEGACY, "get", "/v1/scenes", None).await;
    assert_eq!(status, 200);
    assert!(!body.contains(&beta.scene), "{body}");
    service.shutdown().await;
}

/// The methods of `segsplat.v1.SceneQuery` as the served descriptor lists them.
fn grpc_methods() -> Vec<String> {
    let set = prost_types::FileDescriptorSet::decode(proto::FILE_DESCRIPTOR_SET).unwrap();
    set.file
        .iter()
        .flat_map(|file| &file.service)
        .filter(|service| service.name() == "SceneQuery")
        .flat_map(|service| &service.method)
        .map(|method| method.name().to_string())
        .collect()
}

fn with_token<T>(message: T, token: &str) -> tonic::Request<T> {
    let mut request = tonic::Request::new(message);
    request
        .metadata_mut()
        .insert("authorization", format!("Bearer {token}").parse().unwrap());
    request
}

/// Calls `method` on alpha's scene or job with `token`: `Ok(debug text of the answer)` or the
/// status. Panics for a method without a case here.
async fn call_grpc(
    client: &mut SceneQueryClient<tonic::transport::Channel>,
    method: &str,
    owned: &Owned,
    token: &str,
) -> Result<String, tonic::Status> {
    let scene_id = owned.scene.clone();
    let view = Some(proto::View {
        source: Some(proto::view::Source::FrameIndex(0)),
        time: None,
        max_side: None,
    });
    match method {
        "Query" => client
            .query(with_token(
                proto::QueryRequest {
                    scene_id,
                    text: "mug".to_string(),
                    ..Default::default()
                },
                token,
            ))
            .await
            .map(|answer| format!("{:?}", answer.into_inner())),
        "StreamQuery" => {
            let messages = tokio_stream::iter(vec![proto::StreamQueryRequest {
                scene_id,
                text: "mug".to_string(),
                ..Default::default()
            }]);
            let mut replies = client
                .stream_query(with_token(messages, token))
                .await?
                .into_inner();
            let mut seen = String::new();
            while let Some(reply) = replies.message().await? {
                seen.push_str(&format!("{reply:?}"));
            }
            Ok(seen)
        }
        "ListObjects" => client
            .list_objects(with_token(
                proto::ListObjectsRequest {
                    scene_id,
                    level: 0,
                    time: None,
                },
                token,
            ))
            .await
            .map(|answer| format!("{:?}", answer.into_inner())),
        "RenderMask" => client
            .render_mask(with_token(
                proto::RenderMaskRequest {
                    scene_id,
                    object_id: OBJECT_ID,
                    level: proto::Level::Small as i32,
                    view,
                    mask_encoding: proto::MaskEncoding::Png as i32,
                    ..Default::default()
                },
                token,
            ))
            .await
            .map(|answer| format!("{:?}", answer.into_inner())),
        "GetJob" => client
            .get_job(with_token(
                proto::GetJobRequest {
                    job_id: owned.job.clone(),
                },
                token,
            ))
            .await
            .map(|answer| format!("{:?}", answer.into_inner())),
        "GetScene" => client
            .get_scene(with_token(proto::GetSceneRequest { scene_id }, token))
            .await
            .map(|answer| format!("{:?}", answer.into_inner())),
        "ListCameras" => client
            .list_cameras(with_token(proto::ListCamerasRequest { scene_id }, token))
            .await
            .map(|answer| format!("{:?}", answer.into_inner())),
        "ListScenes" => client
            .list_scenes(with_token(proto::ListScenesRequest {}, token))
            .await
            .map(|answer| format!("{:?}", answer.into_inner())),
        other => panic!("gRPC method {other} has no case in this test: add one"),
    }
}

#[tokio::test]
async fn every_grpc_method_keeps_tenants_apart() {
    let (_dir, service) = start().await;
    let alpha = owned_by(&service, ALPHA).await;
    let beta = owned_by(&service, BETA).await;
    let mut client = service.grpc().await;
    let methods = grpc_methods();
    assert_eq!(methods.len(), 8, "{methods:?}");
    for method in &methods {
        let lists = method.starts_with("List")
            && !["ListObjects", "ListCameras"].contains(&method.as_str());
        match call_grpc(&mut client, method, &alpha, BETA).await {
            Ok(answer) => {
                assert!(
                    lists,
                    "{method}: beta got an answer about alpha's: {answer}"
                );
                assert!(
                    !answer.contains(&alpha.scene) && !answer.contains(&alpha.job),
                    "{method}: beta's list has alpha's: {answer}"
                );
                assert!(answer.contains(&beta.scene), "{method}: {answer}");
            }
            Err(status) => assert_eq!(
                status.code(),
                tonic::Code::NotFound,
                "{method}: beta got {status:?}"
            ),
        }
        for (who, token) in [("alpha", ALPHA), ("admin", ADMIN)] {
            match call_grpc(&mut client, method, &alpha, token).await {
                Ok(answer) => {
                    if lists {
                        assert!(answer.contains(&alpha.scene), "{method} {who}: {answer}");
                    }
                }
                Err(status) => assert!(
                    ![tonic::Code::NotFound, tonic::Code::Unauthenticated].contains(&status.code()),
                    "{method}: {who} got {status:?}"
                ),
            }
        }
    }
    service.shutdown().await;
}

#[tokio::test]
async fn tenant_token_config_is_validated() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.auth.token = vec![tenant_token("t", None, false)];
    let error = config.validate().unwrap_err().to_string();
    assert!(
        error.contains("auth.token[0]") && error.contains("tenant"),
        "{error}"
    );
    config.auth.token = vec![tenant_token("t", Some("has space"), false)];
    assert!(config.validate().is_err());
    config.auth.tokens = vec!["t".to_string()];
    config.auth.token = vec![tenant_token("t", Some("alpha"), false)];
    let error = config.validate().unwrap_err().to_string();
    assert!(error.contains("twice"), "{error}");
    config.auth.tokens = vec![];
    config.auth.token = vec![tenant_token("root", None, true)];
    config.validate().unwrap();
    let parsed: segsplat_service::config::Config = toml::from_str(
        "[auth]\ntokens = [\"old\"]\n[[auth.token]]\ntoken = \"a\"\ntenant = \"alpha\"\n\
         [[auth.token]]\ntoken = \"r\"\nadmin = true\n",
    )
    .unwrap();
    assert_eq!(parsed.auth.token.len(), 2);
    assert!(parsed.auth.token[1].admin);
}
