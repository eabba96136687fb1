//! The REST contract, offline: the served OpenAPI document's invariants (every answer described,
//! open routes without security, the error statuses the server returns, the enums it enforces)
//! for a server with tokens and one without, and the framework's rejections answering in the JSON
//! error envelope. `scripts/contract.sh` checks the same document with openapi-spec-validator
//! and schemathesis against a live server.

mod common;

use std::sync::Arc;

use common::handlers::{STEPS_KIND, StepsHandler};
use common::{TestService, test_config};
use serde_json::{Value, json};

const TOKEN: &str = "contract-token";
const OPEN_PATHS: [&str; 4] = ["/healthz", "/readyz", "/metrics", "/v1/openapi.json"];
const METHODS: [&str; 5] = ["get", "put", "post", "delete", "patch"];

async fn start(auth: bool) -> (tempfile::TempDir, TestService) {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    if auth {
        config.auth.tokens = vec![TOKEN.to_string()];
    }
    let service = TestService::start(config, vec![Arc::new(StepsHandler::new())]).await;
    (dir, service)
}

/// The served document, fetched without a token (it is open).
async fn document(service: &TestService) -> Value {
    let (status, document) = service.get_json("/v1/openapi.json").await;
    assert_eq!(status, 200, "{document}");
    document
}

/// Every operation as (path, method, operation).
fn operations(document: &Value) -> Vec<(String, String, Value)> {
    let mut found = Vec::new();
    for (path, item) in document["paths"].as_object().unwrap() {
        for method in METHODS {
            if let Some(operation) = item.get(method) {
                found.push((path.clone(), method.to_string(), operation.clone()));
            }
        }
    }
    assert!(found.len() >= 20, "{} operations", found.len());
    found
}

fn schema<'a>(document: &'a Value, name: &str) -> &'a Value {
    let schema = &document["components"]["schemas"][name];
    assert!(schema.is_object(), "no schema {name}");
    schema
}

fn strings(value: &Value) -> Vec<&str> {
    value
        .as_array()
        .unwrap_or_else(|| panic!("not an array: {value}"))
        .iter()
        .map(|item| item.as_str().unwrap())
        .collect()
}

fn check_responses(path: &str, method: &str, operation: &Value) {
    let responses = operation["responses"].as_object().unwrap();
    assert!(!responses.is_empty(), "{method} {path} has no responses");
    for (status, response) in responses {
        let description = response["description"].as_str().unwrap_or("");
        assert!(
            !description.trim().is_empty(),
            "{method} {path} {status} has no description"
        );
        // Every error but readiness's 503 (which reports the checks) is the envelope.
        let is_error = status.starts_with('4') || status.starts_with('5');
        if is_error && path != "/readyz" {
            assert_eq!(
                response["content"]["application/json"]["schema"]["$ref"],
                "#/components/schemas/ErrorBody",
                "{method} {path} {status}"
            );
        }
    }
}

fn check_shared_statuses(path: &str, method: &str, operation: &Value, auth: bool) {
    let responses = &operation["responses"];
    let has = |status: &str| responses.get(status).is_some();
    if operation["requestBody"]["content"]["application/json"].is_object() {
        for status in ["400", "413", "415", "422"] {
            assert!(has(status), "{method} {path} lacks {status}");
        }
    }
    if operation["parameters"]
        .as_array()
        .is_some_and(|parameters| {
            parameters
                .iter()
                .any(|parameter| parameter["in"] == "query" || parameter["in"] == "path")
        })
    {
        assert!(has("400"), "{method} {path} lacks 400");
    }
    if OPEN_PATHS.contains(&path) {
        assert_eq!(operation["security"], json!([]), "{method} {path}");
        assert!(!has("401"), "{method} {path} is open but lists 401");
    } else {
        assert!(has("503"), "{method} {path} lacks 503");
        if auth {
            assert_eq!(
                operation["security"],
                json!([{"bearer": []}]),
                "{method} {path}"
            );
            assert!(has("401"), "{method} {path} lacks 401");
        } else {
            assert_eq!(operation["security"], json!([]), "{method} {path}");
            assert!(!has("401"), "{method} {path} lists 401 without tokens");
        }
    }
}

fn check_document(document: &Value, auth: bool) {
    assert!(
        document["openapi"].as_str().unwrap().starts_with("3.1"),
        "{}",
        document["openapi"]
    );
    assert!(
        document.get("security").is_none(),
        "security is per operation"
    );
    for (path, method, operation) in operations(document) {
        check_responses(&path, &method, &operation);
        check_shared_statuses(&path, &method, &operation, auth);
    }
    let scheme = &document["components"]["securitySchemes"]["bearer"];
    if auth {
        assert_eq!(scheme["scheme"], "bearer");
    } else {
        assert!(scheme.is_null(), "{scheme}");
    }

    // What the server enforces is in the schemas.
    assert_eq!(
        strings(&schema(document, "LevelName")["enum"]),
        ["small", "middle", "large"]
    );
    assert_eq!(
        strings(&schema(document, "GranularityName")["enum"]),
        ["auto", "small", "middle", "large"]
    );
    assert_eq!(strings(&schema(document, "JobStateName")["enum"]).len(), 5);
    let kind = &schema(document, "CreateJobRequest")["properties"]["kind"];
    assert_eq!(strings(&kind["enum"]), [STEPS_KIND]);
    let query = &schema(document, "QueryRequest")["properties"];
    assert_eq!(query["text"]["minLength"], 1);
    assert_eq!(query["top_k"]["minimum"], 1);
    assert_eq!(
        query["top_k"]["maximum"],
        segsplat_vision::language::query::MAX_TOP_K
    );
    assert_eq!(query["threshold"]["maximum"], 1.0);
    let objects = &schema(document, "MasksRequest")["properties"]["objects"];
    assert_eq!(objects["minItems"], 1);
    assert_eq!(objects["maxItems"], 64);

    let view = schema(document, "ViewRequest");
    let shapes = view["oneOf"]
        .as_array()
        .expect("a view is one of two shapes");
    let required: Vec<_> = shapes.iter().map(|shape| &shape["required"]).collect();
    assert_eq!(
        required,
        [
            &json!(["frame_index"]),
            &json!(["camera_to_world", "intrinsics"])
        ]
    );
    let upload = &document["paths"]["/v1/scenes"]["post"]["requestBody"]["content"];
    for media_type in ["application/zip", "application/gzip", "multipart/form-data"] {
        assert!(
            upload[media_type]["schema"].is_object(),
            "upload lacks {media_type}"
        );
    }
    assert_eq!(upload["application/zip"]["schema"]["format"], "binary");

    // The event stream and DELETE say what they answer.
    let events = &document["paths"]["/v1/jobs/{id}/events"]["get"]["responses"]["200"];
    assert!(
        events["content"]["text/event-stream"].is_object(),
        "{events}"
    );
    let deleted = &document["paths"]["/v1/scenes/{id}"]["delete"]["responses"]["204"];
    assert!(deleted.get("content").is_none(), "{deleted}");

    check_issue_41_schemas(document);
    check_trained_files(document);
}

/// The trained version's files (issue 41, item 8): one operation per JSON file with its own
/// schema, and the file route for the binary files only, as bytes; a generated client then
/// parses the JSON files as JSON and hands the others back as bytes (scripts/contract.sh runs
/// one against a trained scene).
fn check_trained_files(document: &Value) {
    let paths = &document["paths"];
    let binary = &paths["/v1/scenes/{id}/trained/{file}"]["get"];
    assert_eq!(binary["operationId"], "trained_file");
    let content = binary["responses"]["200"]["content"].as_object().unwrap();
    assert_eq!(
        content.keys().collect::<Vec<_>>(),
        ["application/octet-stream"],
        "{binary}"
    );
    assert_eq!(
        strings(&schema(document, "TrainedBinaryFileName")["enum"]),
        ["scene.ply", "scene.spz", "labels.npy", "deformation.bin"]
    );
    for (file, operation_id, array_of) in [
        ("cameras.json", "trained_cameras", Some("TrainedCamera")),
        ("objects.json", "trained_objects", Some("TrainedObject")),
        ("metrics.json", "trained_metrics", None),
        (
            "skipped_pairs.json",
            "trained_skipped_pairs",
            Some("SkippedFramePair"),
        ),
        ("deformation.json", "trained_deformation", None),
    ] {
        let operation = &paths[format!("/v1/scenes/{{id}}/trained/{file}")]["get"];
        assert_eq!(operation["operationId"], operation_id, "{file}");
        let content = operation["responses"]["200"]["content"]
            .as_object()
            .unwrap();
        assert_eq!(
            content.keys().collect::<Vec<_>>(),
            ["application/json"],
            "{file}"
        );
        let body = &content["application/json"]["schema"];
        match array_of {
            Some(item) => {
                assert_eq!(body["type"], "array", "{file}: {body}");
                assert_eq!(
                    body["items"]["$ref"],
                    format!("#/components/schemas/{item}"),
                    "{file}"
                );
                assert!(schema(document, item)["required"].is_array(), "{item}");
            }
            None => assert_eq!(body["type"], "object", "{file}: {body}"),
        }
    }
}

/// What schemathesis found the document did not say (issue 41, item 9).
fn check_issue_41_schemas(document: &Value) {
    let operation = &document["paths"]["/v1/jobs/{id}/events"]["get"];
    // Each Server-Sent Event is an object (id, event, data), the data a JobEvent as JSON; not
    // `type: string`, which no event is.
    let event = &operation["responses"]["200"]["content"]["text/event-stream"]["schema"];
    assert_eq!(event["type"], "object", "{event}");
    assert_eq!(strings(&event["required"]), ["id", "event", "data"]);
    assert_eq!(
        event["properties"]["data"]["contentSchema"]["$ref"],
        "#/components/schemas/JobEvent"
    );
    // An empty or non-numeric `Last-Event-ID` is refused, and the document says both.
    let last_event_id = operation["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|parameter| parameter["name"] == "Last-Event-ID")
        .expect("Last-Event-ID is declared");
    assert_eq!(last_event_id["in"], "header");
    assert_eq!(
        last_event_id["schema"],
        json!({"type": "integer", "format": "int64", "minimum": 0})
    );
    assert!(operation["responses"]["400"].is_object());
    // A job's config is an object or left out; `null` is not one.
    let config = &schema(document, "CreateJobRequest")["properties"]["config"];
    assert_eq!(config["type"], "object", "{config}");
    // A free camera: the last row of its pose is 0 0 0 1, rigidity is stated, and the image
    // side is bounded by this server's `query.max_mask_side`.
    let shapes = schema(document, "ViewRequest")["oneOf"].as_array().unwrap();
    let pose = &shapes[1]["properties"]["camera_to_world"];
    let last_row: Vec<_> = pose["prefixItems"][3]["prefixItems"]
        .as_array()
        .expect("the last row is spelled out")
        .iter()
        .map(|value| value["enum"][0].as_f64().unwrap())
        .collect();
    assert_eq!(last_row, [0.0, 0.0, 0.0, 1.0], "{pose}");
    assert_eq!(pose["maxItems"], 4, "{pose}");
    assert!(
        pose["description"].as_str().unwrap().contains("rigid"),
        "{pose}"
    );
    let intrinsics = schema(document, "PinholeIntrinsics");
    for side in ["width", "height"] {
        assert_eq!(
            intrinsics["properties"][side]["maximum"],
            segsplat_service::serving::DEFAULT_MAX_MASK_SIDE,
            "{side}"
        );
    }
    // The mask PNG answers 400 for a frame index past the scene's frames.
    let png = &document["paths"]["/v1/scenes/{id}/objects/{level}/{object_id}/mask.png"]["get"];
    assert!(png["responses"]["400"].is_object());
}

#[tokio::test]
async fn the_document_is_true_with_tokens() {
    let (_dir, service) = start(true).await;
    check_document(&document(&service).await, true);
    service.shutdown().await;
}

#[tokio::test]
async fn the_document_is_true_without_tokens() {
    let (_dir, service) = start(false).await;
    check_document(&document(&service).await, false);
    service.shutdown().await;
}

/// Sends a request with the token and returns status, content type and JSON body.
async fn send(
    service: &TestService,
    method: reqwest::Method,
    path: &str,
    content_type: Option<&str>,
    body: Vec<u8>,
) -> (u16, String, Value, Option<String>) {
    let mut request = service
        .client
        .request(method, service.url(path))
        .bearer_auth(TOKEN)
        .body(body);
    if let Some(content_type) = content_type {
        request = request.header("content-type", content_type);
    }
    let response = request.send().await.unwrap();
    let status = response.status().as_u16();
    let header = |name: &str| {
        response
            .headers()
            .get(name)
            .and_then(|value| value.to_str().ok())
            .map(str::to_string)
    };
    let kind = header("content-type").unwrap_or_default();
    let allow = header("allow");
    let text = response.text().await.unwrap();
    let body = serde_json::from_str(&text).unwrap_or(Value::String(text));
    (status, kind, body, allow)
}

/// A request the framework refuses, and what its answer must say.
struct Refused {
    method: reqwest::Method,
    path: &'static str,
    content_type: Option<&'static str>,
    body: Vec<u8>,
    status: u16,
    code: &'static str,
    /// A word the message must contain: it names the problem.
    mentions: &'static str,
}

fn refused(
    method: reqwest::Method,
    path: &'static str,
    (content_type, body): (Option<&'static str>, &[u8]),
    (status, code, mentions): (u16, &'static str, &'static str),
) -> Refused {
    Refused {
        method,
        path,
        content_type,
        body: body.to_vec(),
        status,
        code,
        mentions,
    }
}

#[tokio::test]
async fn framework_rejections_answer_in_the_error_envelope() {
    use reqwest::Method;
    let (_dir, service) = start(true).await;
    let none = (None, &b""[..]);
    let json = |body: &'static [u8]| (Some("application/json"), body);
    let big = format!("{{\"text\": \"{}\"}}", "a".repeat(3 << 20)).into_bytes();
    let query = "/v1/scenes/s/query";
    let cases = [
        refused(
            Method::GET,
            "/v1/scenes/s/objects?time=soon",
            none,
            (400, "bad_request", "time"),
        ),
        refused(
            Method::GET,
            "/v1/jobs?state=a&state=b",
            none,
            (400, "bad_request", "state"),
        ),
        refused(
            Method::POST,
            query,
            json(b"{"),
            (400, "bad_request", "JSON"),
        ),
        refused(
            Method::POST,
            query,
            (Some("text/plain"), b"{}"),
            (415, "unsupported_media_type", "application/json"),
        ),
        refused(
            Method::POST,
            query,
            json(br#"{"txt": 1}"#),
            (422, "invalid_input", "txt"),
        ),
        refused(
            Method::POST,
            query,
            (Some("application/json"), &big),
            (413, "payload_too_large", "limit"),
        ),
        refused(
            Method::GET,
            "/v1/scenes/s/objects/small/seven/ply",
            none,
            (400, "bad_request", "seven"),
        ),
        refused(
            Method::POST,
            query,
            json(br#"{"text": "x", "top_k": 0.5}"#),
            (422, "invalid_input", "top_k"),
        ),
        // A whole number written as a float is an integer, as in JSON Schema: it passes and
        // the request reaches the scene lookup.
        refused(
            Method::POST,
            query,
            json(br#"{"text": "x", "top_k": 2.0}"#),
            (404, "not_found", "scene"),
        ),
        // `config` is an object or left out (issue 41): `null` was taken as the defaults.
        refused(
            Method::POST,
            "/v1/scenes/s/jobs",
            json(br#"{"kind": "steps", "config": null}"#),
            (422, "invalid_input", "config"),
        ),
        refused(
            Method::POST,
            "/v1/scenes/s/jobs",
            json(br#"{"kind": "steps", "config": [1]}"#),
            (422, "invalid_input", "config"),
        ),
        refused(
            Method::GET,
            "/v1/nowhere",
            none,
            (404, "not_found", "endpoint"),
        ),
        refused(
            Method::PUT,
            "/v1/scenes",
            none,
            (405, "method_not_allowed", "method"),
        ),
    ];
    for case in cases {
        let label = format!("{} {}", case.method, case.path);
        let (status, kind, body, allow) = send(
            &service,
            case.method,
            case.path,
            case.content_type,
            case.body,
        )
        .await;
        assert_eq!(status, case.status, "{label}: {body}");
        assert!(kind.starts_with("application/json"), "{label}: {kind}");
        assert_eq!(body["error"]["code"], case.code, "{label}: {body}");
        let message = body["error"]["message"].as_str().unwrap_or("");
        assert!(message.contains(case.mentions), "{label}: {message}");
        if status == 405 {
            let allow = allow.unwrap_or_default();
            assert!(allow.contains("GET") && allow.contains("POST"), "{allow}");
        }
    }
    service.shutdown().await;
}

/// `Last-Event-ID` must be an event id: empty or not a whole number from 0 is a 400 (issue 41),
/// not "from the start". A good one reaches the job lookup.
#[tokio::test]
async fn a_bad_last_event_id_is_refused() {
    let (_dir, service) = start(true).await;
    for (value, status) in [
        ("", 400),
        ("null", 400),
        ("abc", 400),
        ("-1", 400),
        ("1.5", 400),
        ("7", 404),
    ] {
        let response = service
            .client
            .get(service.url("/v1/jobs/nosuchjob/events"))
            .bearer_auth(TOKEN)
            .header("last-event-id", value)
            .send()
            .await
            .unwrap();
        assert_eq!(response.status().as_u16(), status, "{value:?}");
        let body: Value = response.json().await.unwrap();
        if status == 400 {
            assert_eq!(body["error"]["code"], "bad_request", "{body}");
            assert!(
                body["error"]["message"]
                    .as_str()
                    .unwrap()
                    .contains("Last-Event-ID"),
                "{body}"
            );
        }
    }
    service.shutdown().await;
}
