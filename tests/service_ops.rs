//! Ops and access: health, readiness, metrics, OpenAPI, bearer tokens on REST and gRPC, the gRPC
//! health service and the gRPC scene/job/object reads.

mod common;

use std::sync::Arc;

use common::handlers::{STEPS_KIND, StepsHandler};
use common::{TestService, test_config};
use segsplat_api::proto;
use segsplat_api::proto::scene_query_client::SceneQueryClient;
use segsplat_scene::Level;
use segsplat_service::store::objects::{ObjectEmbedding, ObjectRecord};
use serde_json::json;
use tonic_health::pb::HealthCheckRequest;
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::health_client::HealthClient;

async fn grpc_channel(service: &TestService) -> tonic::transport::Channel {
    let addr = service.service.grpc_addr().unwrap();
    tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
        .unwrap()
        .connect()
        .await
        .unwrap()
}

#[tokio::test]
async fn health_readiness_metrics_and_openapi() {
    let dir = tempfile::tempdir().unwrap();
    let service = TestService::start(test_config(dir.path()), vec![]).await;
    let (status, body) = service.get_json("/healthz").await;
    assert_eq!((status, body["status"].as_str()), (200, Some("ok")));

    // GPU discovery is off in tests, so the service runs but says why it is not ready.
    let (status, body) = service.get_json("/readyz").await;
    assert_eq!(status, 503, "{body}");
    assert_eq!(body["ready"], false);
    assert_eq!(body["checks"]["database"]["ok"], true);
    assert_eq!(body["checks"]["adapters"]["ok"], false);
    assert_eq!(body["checks"]["models"]["detail"], "none configured");
    let reasons = body["reasons"].as_array().unwrap();
    assert!(
        reasons
            .iter()
            .any(|r| r.as_str().unwrap().starts_with("adapters:")),
        "{body}"
    );

    // Workers disabled in this process: adapters do not matter for readiness.
    let dir2 = tempfile::tempdir().unwrap();
    let mut config = test_config(dir2.path());
    config.workers.enabled = false;
    let api_only = TestService::start(config, vec![]).await;
    let (status, body) = api_only.get_json("/readyz").await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["ready"], true);
    api_only.shutdown().await;

    let (status, _) = service.get_json("/v1/scenes").await;
    assert_eq!(status, 200);
    let (status, body) = service.get_json("/v1/nowhere").await;
    assert_eq!(status, 404);
    assert_eq!(body["error"]["code"], "not_found");
    let metrics = service
        .client
        .get(service.url("/metrics"))
        .send()
        .await
        .unwrap();
    assert_eq!(metrics.status().as_u16(), 200);
    let text = metrics.text().await.unwrap();
    assert!(text.contains("segsplat_http_requests_total{"), "{text}");
    assert!(text.contains("route=\"/v1/scenes\""), "{text}");
    assert!(
        text.contains("segsplat_http_request_duration_seconds_bucket{"),
        "{text}"
    );
    assert!(text.contains("segsplat_jobs{state=\"queued\"}"), "{text}");

    let (status, doc) = service.get_json("/v1/openapi.json").await;
    assert_eq!(status, 200);
    assert!(doc["openapi"].as_str().unwrap().starts_with('3'));
    for path in [
        "/v1/scenes",
        "/v1/scenes/{id}",
        "/v1/scenes/{id}/jobs",
        "/v1/jobs",
        "/v1/jobs/{id}",
        "/v1/jobs/{id}/cancel",
        "/v1/jobs/{id}/events",
        "/readyz",
    ] {
        assert!(doc["paths"][path].is_object(), "OpenAPI lacks {path}");
    }
    assert!(doc["components"]["schemas"]["SceneResponse"].is_object());
    service.shutdown().await;
}

#[tokio::test]
async fn bearer_tokens_guard_rest_and_grpc_when_configured() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.auth.tokens = vec!["s3cret".to_string()];
    let service = TestService::start(config, vec![]).await;

    let response = service
        .client
        .get(service.url("/v1/scenes"))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 401);
    let body: serde_json::Value = response.json().await.unwrap();
    assert_eq!(body["error"]["code"], "unauthorized");
    let response = service
        .client
        .get(service.url("/v1/scenes"))
        .bearer_auth("wrong")
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 401);
    let response = service
        .client
        .get(service.url("/v1/scenes"))
        .bearer_auth("s3cret")
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 200);
    let response = service
        .client
        .post(service.url("/v1/scenes"))
        .header("content-type", "application/zip")
        .body(vec![1, 2, 3])
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 401);
    for open in ["/healthz", "/readyz", "/metrics"] {
        let status = service
            .client
            .get(service.url(open))
            .send()
            .await
            .unwrap()
            .status();
        assert_ne!(status.as_u16(), 401, "{open} must stay open");
    }
    // `/readyz` is open, but only says whether the service is ready; its details (checks with
    // server paths, reasons, adapters, workers) need a valid token (issue 41).
    let readyz = |token: Option<&'static str>| {
        let mut request = service.client.get(service.url("/readyz"));
        if let Some(token) = token {
            request = request.bearer_auth(token);
        }
        async move {
            let response = request.send().await.unwrap();
            let status = response.status().as_u16();
            (status, response.json::<serde_json::Value>().await.unwrap())
        }
    };
    for token in [None, Some("wrong")] {
        let (status, body) = readyz(token).await;
        assert_eq!(status, 503, "{body}");
        let keys: Vec<&String> = body.as_object().unwrap().keys().collect();
        assert_eq!(keys, ["ready"], "{token:?}: {body}");
        assert_eq!(body["ready"], false);
    }
    let (status, body) = readyz(Some("s3cret")).await;
    assert_eq!(status, 503, "{body}");
    assert_eq!(body["checks"]["database"]["ok"], true, "{body}");
    assert!(
        body["reasons"]
            .as_array()
            .is_some_and(|reasons| !reasons.is_empty())
    );
    assert!(body["cluster"].is_object(), "{body}");

    let channel = grpc_channel(&service).await;
    let mut health = HealthClient::new(channel.clone());
    let answer = health
        .check(HealthCheckRequest {
            service: String::new(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        answer.status,
        ServingStatus::Serving as i32,
        "health is exempt"
    );
    let mut client = SceneQueryClient::new(channel.clone());
    let denied = client
        .list_scenes(proto::ListScenesRequest {})
        .await
        .unwrap_err();
    assert_eq!(denied.code(), tonic::Code::Unauthenticated);
    let mut request = tonic::Request::new(proto::ListScenesRequest {});
    request
        .metadata_mut()
        .insert("authorization", "Bearer s3cret".parse().unwrap());
    assert!(client.list_scenes(request).await.is_ok());

    // Reflection describes the API (no tenant's data): open, like health, so grpcurl can
    // resolve a health check without a token (issue 41). The rest stays behind the token.
    use tonic_reflection::pb::v1::ServerReflectionRequest;
    use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
    use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
    use tonic_reflection::pb::v1::server_reflection_response::MessageResponse as V1Response;
    let ask = |message: MessageRequest| ServerReflectionRequest {
        host: String::new(),
        message_request: Some(message),
    };
    let mut reflection = ServerReflectionClient::new(channel.clone());
    // An unknown symbol is answered inside the stream (ErrorResponse, NOT_FOUND), and the
    // stream goes on: the next questions are answered too.
    let requests = tokio_stream::iter(vec![
        ask(MessageRequest::FileContainingSymbol(
            "segsplat.v1.NoSuchService".to_string(),
        )),
        ask(MessageRequest::ListServices(String::new())),
        ask(MessageRequest::FileContainingSymbol(
            "grpc.health.v1.Health".to_string(),
        )),
        ask(MessageRequest::FileByFilename("nowhere.proto".to_string())),
        ask(MessageRequest::FileContainingSymbol(
            "segsplat.v1.SceneQuery.Query".to_string(),
        )),
    ]);
    let mut answers = reflection
        .server_reflection_info(requests)
        .await
        .expect("reflection needs no token")
        .into_inner();
    macro_rules! next {
        () => {
            answers
                .message()
                .await
                .expect("the stream goes on")
                .expect("an answer per question")
                .message_response
                .expect("a response")
        };
    }
    let V1Response::ErrorResponse(unknown) = next!() else {
        panic!("an unknown symbol is an in-stream error");
    };
    assert_eq!(unknown.error_code, tonic::Code::NotFound as i32);
    assert!(
        unknown.error_message.contains("NoSuchService"),
        "{unknown:?}"
    );
    let V1Response::ListServicesResponse(listed) = next!() else {
        panic!("services are listed after an error");
    };
    let names: Vec<&str> = listed.service.iter().map(|s| s.name.as_str()).collect();
    for expected in [
        "segsplat.v1.SceneQuery",
        "grpc.health.v1.Health",
        "grpc.reflection.v1.ServerReflection",
        "grpc.reflection.v1alpha.ServerReflection",
    ] {
        assert!(names.contains(&expected), "{names:?}");
    }
    let V1Response::FileDescriptorResponse(health_file) = next!() else {
        panic!("the health service resolves");
    };
    assert!(!health_file.file_descriptor_proto.is_empty());
    assert!(matches!(next!(), V1Response::ErrorResponse(_)));
    let V1Response::FileDescriptorResponse(api_file) = next!() else {
        panic!("a method resolves to its file");
    };
    use prost::Message as _;
    let file =
        prost_types::FileDescriptorProto::decode(&api_file.file_descriptor_proto[0][..]).unwrap();
    assert_eq!(file.package(), "segsplat.v1");

    // The older v1alpha protocol too, which many clients still speak.
    use tonic_reflection::pb::v1alpha::ServerReflectionRequest as AlphaRequest;
    use tonic_reflection::pb::v1alpha::server_reflection_client::ServerReflectionClient as Alpha;
    use tonic_reflection::pb::v1alpha::server_reflection_request::MessageRequest as AlphaMessage;
    use tonic_reflection::pb::v1alpha::server_reflection_response::MessageResponse;
    let request = tonic::Request::new(tokio_stream::iter(vec![AlphaRequest {
        host: String::new(),
        message_request: Some(AlphaMessage::ListServices(String::new())),
    }]));
    let mut answers = Alpha::new(channel.clone())
        .server_reflection_info(request)
        .await
        .unwrap()
        .into_inner();
    let answer = answers.message().await.unwrap().unwrap();
    let Some(MessageResponse::ListServicesResponse(listed)) = answer.message_response else {
        panic!("v1alpha list_services answered {answer:?}");
    };
    assert!(
        listed
            .service
            .iter()
            .any(|service| service.name == "segsplat.v1.SceneQuery"),
        "{listed:?}"
    );
    service.shutdown().await;
}

#[tokio::test]
async fn grpc_health_and_scene_job_object_reads_without_auth() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let service = TestService::start(test_config(dir.path()), vec![Arc::new(handler)]).await;
    let scene_id = service.upload_test_scene().await;
    let job_id = service
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 1}))
        .await;
    service
        .wait_for_state(&job_id, "succeeded", std::time::Duration::from_secs(15))
        .await;

    let objects = vec![
        ObjectRecord {
            scene_id: scene_id.clone(),
            level: Level::Small,
            object_id: 1,
            gaussian_count: 120,
            centroid: [0.1, 0.2, 0.3],
            bounds_min: [-1.0, -1.0, -1.0],
            bounds_max: [1.0, 1.0, 1.0],
            mean_color: [0.5, 0.25, 0.0],
        },
        ObjectRecord {
            scene_id: scene_id.clone(),
            level: Level::Large,
            object_id: 7,
            gaussian_count: 500,
            centroid: [0.0, 0.0, 0.0],
            bounds_min: [-2.0, -2.0, -2.0],
            bounds_max: [2.0, 2.0, 2.0],
            mean_color: [0.1, 0.1, 0.1],
        },
    ];
    let embeddings = vec![ObjectEmbedding {
        scene_id: scene_id.clone(),
        level: Level::Small,
        object_id: 1,
        model_id: "clip-test".to_string(),
        vector: vec![0.25, -0.5, 1.0],
    }];
    let database = service.service.database();
    database
        .replace_objects(&scene_id, &objects, &embeddings)
        .await
        .unwrap();
    let stored = database
        .list_embeddings(&scene_id, "clip-test")
        .await
        .unwrap();
    assert_eq!(stored, embeddings);

    let channel = grpc_channel(&service).await;
    let mut health = HealthClient::new(channel.clone());
    for name in ["", "segsplat.v1.SceneQuery"] {
        let answer = health
            .check(HealthCheckRequest {
                service: name.to_string(),
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(answer.status, ServingStatus::Serving as i32, "{name:?}");
    }

    let mut client = SceneQueryClient::new(channel);
    let scene = client
        .get_scene(proto::GetSceneRequest {
            scene_id: scene_id.clone(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(scene.format, "colmap");
    assert_eq!(scene.frame_count, 4);
    let scenes = client
        .list_scenes(proto::ListScenesRequest {})
        .await
        .unwrap()
        .into_inner();
    assert_eq!(scenes.scenes.len(), 1);
    let job = client
        .get_job(proto::GetJobRequest {
            job_id: job_id.clone(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(job.state, proto::JobState::Succeeded as i32);
    assert_eq!(job.progress.unwrap().step, 1);
    let missing = client
        .get_job(proto::GetJobRequest {
            job_id: "nope".to_string(),
        })
        .await
        .unwrap_err();
    assert_eq!(missing.code(), tonic::Code::NotFound);

    let all = client
        .list_objects(proto::ListObjectsRequest {
            scene_id: scene_id.clone(),
            level: 0,
            time: None,
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(all.objects.len(), 2);
    let large = client
        .list_objects(proto::ListObjectsRequest {
            scene_id: scene_id.clone(),
            level: proto::Level::Large as i32,
            time: None,
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(large.objects.len(), 1);
    assert_eq!(large.objects[0].object_id, 7);
    assert_eq!(large.objects[0].gaussian_count, 500);
    assert_eq!(large.objects[0].bounds.unwrap().max.unwrap().x, 2.0);

    let no_encoder = client
        .query(proto::QueryRequest {
            scene_id,
            text: "mug".to_string(),
            ..Default::default()
        })
        .await
        .unwrap_err();
    assert_eq!(no_encoder.code(), tonic::Code::Unavailable);
    assert!(no_encoder.message().contains("no text encoder configured"));
    service.shutdown().await;
}
