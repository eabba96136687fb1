//! What every REST operation shares, added to the generated document in one place instead of
//! being repeated on each handler's annotation: the answers of the framework's rejections
//! (`extract.rs`), of the token check (`auth.rs`) and of an unreachable store (`error.rs`), and
//! each operation's security.

use serde_json::{Map, Value, json};

use super::auth::OPEN_PATHS;

const METHODS: [&str; 8] = [
    "get", "put", "post", "delete", "options", "head", "patch", "trace",
];

/// The name of the bearer scheme in `components.securitySchemes`.
const BEARER: &str = "bearer";

/// Calls `visit` with each operation's path and the operation.
fn each_operation(document: &mut Value, mut visit: impl FnMut(&str, &mut Map<String, Value>)) {
    let Some(paths) = document.get_mut("paths").and_then(Value::as_object_mut) else {
        return;
    };
    for (path, item) in paths.iter_mut() {
        for method in METHODS {
            if let Some(operation) = item.get_mut(method).and_then(Value::as_object_mut) {
                visit(path, operation);
            }
        }
    }
}

fn is_open(path: &str) -> bool {
    OPEN_PATHS.contains(&path)
}

/// Adds `status` with the error envelope to `operation`'s responses; a status the handler
/// already declares keeps its own description, followed by `description`.
fn add_error(operation: &mut Map<String, Value>, status: &str, description: &str) {
    let responses = operation
        .entry("responses")
        .or_insert_with(|| json!({}))
        .as_object_mut();
    let Some(responses) = responses else {
        return;
    };
    let envelope = json!({"schema": {"$ref": "#/components/schemas/ErrorBody"}});
    match responses.get_mut(status).and_then(Value::as_object_mut) {
        Some(existing) => {
            let own = existing
                .get("description")
                .and_then(Value::as_str)
                .unwrap_or("")
                .to_string();
            let merged = if own.is_empty() {
                description.to_string()
            } else {
                format!("{own}; or {description}")
            };
            existing.insert("description".to_string(), Value::from(merged));
            let content = existing.entry("content").or_insert_with(|| json!({}));
            if let Some(content) = content.as_object_mut() {
                content
                    .entry("application/json")
                    .or_insert_with(|| envelope.clone());
            }
        }
        None => {
            responses.insert(
                status.to_string(),
                json!({"description": description, "content": {"application/json": envelope}}),
            );
        }
    }
}

fn takes_json_body(operation: &Map<String, Value>) -> bool {
    operation
        .get("requestBody")
        .and_then(|body| body.get("content"))
        .and_then(|content| content.get("application/json"))
        .is_some()
}

fn takes_parameters(operation: &Map<String, Value>) -> bool {
    operation
        .get("parameters")
        .and_then(Value::as_array)
        .is_some_and(|parameters| {
            parameters
                .iter()
                .any(|parameter| matches!(parameter["in"].as_str(), Some("path" | "query")))
        })
}

/// The statuses any handler's input can get before the handler runs, and the store's 503.
pub fn add_shared_responses(document: &mut Value, auth: bool) {
    each_operation(document, |path, operation| {
        if takes_parameters(operation) {
            add_error(
                operation,
                "400",
                "a path segment or query parameter does not parse as its type",
            );
        }
        if takes_json_body(operation) {
            add_error(operation, "400", "the body is not well-formed JSON");
            add_error(
                operation,
                "413",
                "the body is larger than the JSON limit (2 MiB)",
            );
            add_error(
                operation,
                "415",
                "the body is not sent as `Content-Type: application/json`",
            );
            add_error(
                operation,
                "422",
                "the JSON does not fit the schema (a missing or unknown field, a wrong type)",
            );
        }
        if !is_open(path) {
            if auth {
                add_error(
                    operation,
                    "401",
                    "no bearer token, or not one this server accepts",
                );
            }
            add_error(
                operation,
                "503",
                "a store the service depends on (database, blob store) is unreachable; retry",
            );
        }
    });
}

/// Open paths need no token (`security: []`). The others need a bearer token when tokens are
/// configured, and nothing otherwise: the document states what this server checks.
pub fn declare_security(document: &mut Value, auth: bool) {
    each_operation(document, |path, operation| {
        let security = if auth && !is_open(path) {
            json!([{ BEARER: [] }])
        } else {
            json!([])
        };
        operation.insert("security".to_string(), security);
    });
    if let Some(root) = document.as_object_mut() {
        root.remove("security");
        if auth {
            let components = root.entry("components").or_insert_with(|| json!({}));
            if let Some(components) = components.as_object_mut() {
                components.insert(
                    "securitySchemes".to_string(),
                    json!({ BEARER: {"type": "http", "scheme": "bearer"} }),
                );
            }
        }
    }
}
