//! The web console as the binary serves it (docs/console.md): the page and every file its
//! modules import load without a token, with a content security policy; its settings name the
//! Grafana dashboard; the API behind it still needs the token. The browser tests
//! (scripts/console_e2e.sh) drive the console itself.

mod common;

use std::collections::BTreeSet;

use common::{TestService, test_config};

async fn start(grafana: Option<&str>) -> (tempfile::TempDir, TestService) {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.auth.tokens = vec!["console-secret".to_string()];
    config.console.grafana_url = grafana.map(str::to_string);
    let service = TestService::start(config, vec![]).await;
    (dir, service)
}

async fn get(service: &TestService, path: &str) -> reqwest::Response {
    service.client.get(service.url(path)).send().await.unwrap()
}

/// The `./name.js` modules a console file imports, and the `/console/...` files the page links.
fn referenced_files(text: &str) -> BTreeSet<String> {
    let mut files = BTreeSet::new();
    for (marker, end) in [("from \"./", '"'), ("\"/console/", '"')] {
        for (index, _) in text.match_indices(marker) {
            let rest = &text[index + marker.len()..];
            if let Some(length) = rest.find(end) {
                files.insert(rest[..length].to_string());
            }
        }
    }
    files
}

#[tokio::test]
async fn the_console_and_every_file_it_loads_are_served_without_a_token() {
    let (_dir, service) = start(None).await;
    let page = get(&service, "/").await;
    assert_eq!(page.status(), 200);
    let headers = page.headers().clone();
    assert_eq!(headers["content-type"], "text/html; charset=utf-8");
    let policy = headers["content-security-policy"].to_str().unwrap();
    assert!(policy.contains("script-src 'self'"), "{policy}");
    assert_eq!(headers["cache-control"], "no-cache");
    let html = page.text().await.unwrap();
    assert!(html.contains("segsplat console"));

    // Follow the imports from the page through every module: each must be served.
    let mut pending: Vec<String> = referenced_files(&html).into_iter().collect();
    let mut served = BTreeSet::new();
    while let Some(file) = pending.pop() {
        if !served.insert(file.clone()) {
            continue;
        }
        let response = get(&service, &format!("/console/{file}")).await;
        assert_eq!(response.status(), 200, "/console/{file} is not served");
        let content_type = response.headers()["content-type"]
            .to_str()
            .unwrap()
            .to_string();
        let expected = match file.rsplit('.').next() {
            Some("js") => "text/javascript",
            Some("css") => "text/css",
            _ => "application/json",
        };
        assert!(content_type.starts_with(expected), "{file}: {content_type}");
        let text = response.text().await.unwrap();
        pending.extend(referenced_files(&text));
    }
    assert!(
        served.contains("app.js") && served.contains("splat_renderer.js"),
        "{served:?}"
    );

    let missing = get(&service, "/console/nope.js").await;
    assert_eq!(missing.status(), 404);
    let body: serde_json::Value = missing.json().await.unwrap();
    assert_eq!(body["error"]["code"], "not_found", "{body}");
    service.shutdown().await;
}

#[tokio::test]
async fn the_api_behind_the_console_still_needs_the_token() {
    let (_dir, service) = start(Some("http://grafana.example:3000/d/segsplat")).await;
    let settings: serde_json::Value = get(&service, "/console/config.json")
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(settings["auth_required"], true, "{settings}");
    assert_eq!(
        settings["grafana_url"], "http://grafana.example:3000/d/segsplat",
        "{settings}"
    );
    assert_eq!(get(&service, "/v1/scenes").await.status(), 401);
    let with_token = service
        .client
        .get(service.url("/v1/scenes"))
        .bearer_auth("console-secret")
        .send()
        .await
        .unwrap();
    assert_eq!(with_token.status(), 200);
    service.shutdown().await;
}

#[tokio::test]
async fn without_tokens_the_console_says_none_is_needed() {
    let dir = tempfile::tempdir().unwrap();
    let service = TestService::start(test_config(dir.path()), vec![]).await;
    let settings: serde_json::Value = get(&service, "/console/config.json")
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(settings["auth_required"], false, "{settings}");
    assert!(settings["grafana_url"].is_null(), "{settings}");
    service.shutdown().await;
}
