//! The web console (docs/console.md): static files compiled into the binary, served at `/` and
//! `/console/{file}`. They hold no data and need no token to load; everything they show comes
//! from the public REST API, which the console calls with the bearer token the user enters.
//!
//! Plain ES modules with no build step: the binary stays one file that needs nothing beside it,
//! and `cargo build` needs no npm.

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use super::auth::TokenCheck;
use super::error::ApiError;
use super::extract::UrlPath;
use super::state::AppState;

/// Where the console lives; the auth middleware lets these paths through without a token.
pub const CONSOLE_PREFIX: &str = "/console/";

/// Scripts and styles from this origin only, no inline code; images may be `blob:` (masks the
/// console fetched with its token) or `data:`.
const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; img-src 'self' blob: data:; \
     connect-src 'self'; style-src 'self'; script-src 'self'; object-src 'none'; \
     base-uri 'none'; frame-ancestors 'none'";

macro_rules! console_files {
    ($($name:literal => $mime:literal),* $(,)?) => {
        /// (file name, content type, contents) of every console file.
        const FILES: &[(&str, &str, &str)] = &[
            $(($name, $mime, include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../console/", $name)))),*
        ];
    };
}

console_files! {
    "index.html" => "text/html; charset=utf-8",
    "style.css" => "text/css; charset=utf-8",
    "app.js" => "text/javascript; charset=utf-8",
    "api.js" => "text/javascript; charset=utf-8",
    "dom.js" => "text/javascript; charset=utf-8",
    "scenes.js" => "text/javascript; charset=utf-8",
    "jobs.js" => "text/javascript; charset=utf-8",
    "chart.js" => "text/javascript; charset=utf-8",
    "scene_view.js" => "text/javascript; charset=utf-8",
    "splat_files.js" => "text/javascript; charset=utf-8",
    "splat_renderer.js" => "text/javascript; charset=utf-8",
    "orbit.js" => "text/javascript; charset=utf-8",
    "status.js" => "text/javascript; charset=utf-8",
}

fn console_file(name: &str) -> Option<Response> {
    let (_, mime, body) = FILES.iter().find(|(file, _, _)| *file == name)?;
    let mut response = (*body).into_response();
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(mime));
    // Revalidated on every load, so an upgraded binary's console is never mixed with a cached one.
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    headers.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CONTENT_SECURITY_POLICY),
    );
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    Some(response)
}

pub async fn index() -> Response {
    console_file("index.html").unwrap_or_else(|| ApiError::not_found("no console").into_response())
}

pub async fn asset(UrlPath(name): UrlPath<String>) -> Response {
    console_file(&name).unwrap_or_else(|| {
        ApiError::not_found(format!("the console has no file {name:?}")).into_response()
    })
}

/// What the console needs to know of the server's configuration, none of it secret.
#[derive(Debug, Serialize)]
pub struct ConsoleSettings {
    /// Every API route needs a bearer token.
    pub auth_required: bool,
    pub grafana_url: Option<String>,
    pub version: &'static str,
}

pub async fn settings(State(state): State<AppState>) -> Json<ConsoleSettings> {
    let config = &state.core.config;
    Json(ConsoleSettings {
        // The rule the API's own token check follows, so the two never disagree.
        auth_required: TokenCheck::from_config(&config.auth).enabled(),
        grafana_url: config.console.grafana_url.clone(),
        version: env!("CARGO_PKG_VERSION"),
    })
}

/// Paths the console serves without a token: the page and its files, nothing with data.
pub fn is_console_path(path: &str) -> bool {
    path == "/" || path.starts_with(CONSOLE_PREFIX)
}
