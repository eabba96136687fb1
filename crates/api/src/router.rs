//! The REST routes and their middleware.

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::routing::{get, post};
use tower_http::trace::TraceLayer;

use super::auth::{TokenCheck, require_token};
use super::metrics::track_requests;
use super::state::AppState;
use super::{
    console, exports, extract, jobs, masks, objects, openapi, ops, query, scenes, workers,
};

pub fn router(state: AppState) -> Router {
    let tokens = TokenCheck::from_config(&state.core.config.auth);
    Router::new()
        .route(
            "/v1/scenes",
            post(scenes::upload_scene)
                .layer(DefaultBodyLimit::disable())
                .get(scenes::list_scenes),
        )
        .route(
            "/v1/scenes/{id}",
            get(scenes::get_scene).delete(scenes::delete_scene),
        )
        .route("/v1/scenes/{id}/jobs", post(jobs::create_job))
        .route("/v1/scenes/{id}/objects", get(objects::list_objects))
        .route("/v1/scenes/{id}/query", post(query::query_scene))
        .route("/v1/scenes/{id}/masks", post(masks::render_masks))
        .route(
            "/v1/scenes/{id}/objects/{level}/{object_id}/mask.png",
            get(masks::object_mask_png),
        )
        .route(
            "/v1/scenes/{id}/objects/{level}/{object_id}/ply",
            get(exports::object_ply),
        )
        .route(
            "/v1/scenes/{id}/objects/{level}/{object_id}/spz",
            get(exports::object_spz),
        )
        // The JSON files before the file route: each has its own operation in the document.
        .route(
            "/v1/scenes/{id}/trained/cameras.json",
            get(exports::trained_cameras),
        )
        .route(
            "/v1/scenes/{id}/trained/objects.json",
            get(exports::trained_objects),
        )
        .route(
            "/v1/scenes/{id}/trained/metrics.json",
            get(exports::trained_metrics),
        )
        .route(
            "/v1/scenes/{id}/trained/skipped_pairs.json",
            get(exports::trained_skipped_pairs),
        )
        .route(
            "/v1/scenes/{id}/trained/deformation.json",
            get(exports::trained_deformation),
        )
        .route("/v1/scenes/{id}/trained/{file}", get(exports::trained_file))
        .route("/v1/jobs", get(jobs::list_jobs))
        .route("/v1/jobs/{id}", get(jobs::get_job))
        .route("/v1/jobs/{id}/cancel", post(jobs::cancel_job))
        .route("/v1/jobs/{id}/events", get(jobs::job_events))
        .route("/v1/workers", get(workers::list_workers))
        .route("/v1/openapi.json", get(openapi::openapi_json))
        .route("/healthz", get(ops::healthz))
        .route("/readyz", get(ops::readyz))
        .route("/metrics", get(ops::metrics))
        // The web console (docs/console.md); `config.json` before the catch-all file route.
        .route("/", get(console::index))
        .route("/console/config.json", get(console::settings))
        .route("/console/{file}", get(console::asset))
        // After the routes: it applies to those already added.
        .method_not_allowed_fallback(extract::method_not_allowed)
        .fallback(extract::no_such_endpoint)
        .layer(axum::middleware::from_fn_with_state(tokens, require_token))
        .layer(axum::middleware::from_fn(track_requests))
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

/// A worker process's listener: only the probes and `/metrics` (open, as on the API), so
/// orchestrators can check it and Prometheus can scrape its training and queue metrics.
pub fn ops_router(state: AppState) -> Router {
    Router::new()
        .route("/healthz", get(ops::healthz))
        .route("/readyz", get(ops::readyz))
        .route("/metrics", get(ops::metrics))
        .fallback(|| async {
            super::error::ApiError::not_found(
                "a worker process serves only /healthz, /readyz and /metrics",
            )
        })
        .layer(axum::middleware::from_fn(track_requests))
        .with_state(state)
}
