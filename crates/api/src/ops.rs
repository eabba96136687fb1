//! Liveness, readiness and metrics endpoints.

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::IntoResponse;
use serde::Serialize;
use utoipa::ToSchema;

use super::auth::TokenCheck;
use super::metrics::{refresh_cluster_gauges, refresh_queue_gauges};
use super::readiness::{ANSWER_WITHIN, Reading};
use super::state::AppState;
use segsplat_service::core::ServiceCore;
use segsplat_service::usecases::workers::{cluster_workers, summarize};

#[derive(Debug, Serialize, ToSchema)]
pub struct HealthResponse {
    pub status: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ReadinessCheck {
    pub ok: bool,
    pub detail: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ReadinessChecks {
    pub database: ReadinessCheck,
    /// The blob store (local directory or S3-compatible bucket) answers a listing.
    pub blobs: ReadinessCheck,
    pub adapters: ReadinessCheck,
    pub models: ReadinessCheck,
}

/// `/readyz`'s answer. Everyone gets `ready` (and the status: 200 or 503), what a probe needs.
/// The details (why not, each check with server paths and driver messages, the adapters, the
/// cluster's workers) come only with a valid bearer token when tokens are configured, and to
/// everyone when none are: they describe the deployment, which an open endpoint should not.
#[derive(Debug, Serialize, ToSchema)]
pub struct ReadinessResponse {
    pub ready: bool,
    /// Why the service is not ready; empty when it is. With a token (or without tokens
    /// configured) only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reasons: Option<Vec<String>>,
    /// With a token (or without tokens configured) only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub checks: Option<ReadinessChecks>,
    /// The GPU adapters workers use (as reported by wgpu). With a token only.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<Object>>)]
    pub adapters: Option<Vec<segsplat_gpu::AdapterReport>>,
    /// Worker slots of every process on this database (`GET /v1/workers` lists them). With a
    /// token only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<ClusterWorkers>,
}

/// Whether this request may see `/readyz`'s details: tokens are not configured, or it carries
/// one of them (any tenant's).
fn sees_details(state: &AppState, headers: &HeaderMap) -> bool {
    let auth = &state.core.config.auth;
    if !auth.enabled() {
        return true;
    }
    let header = headers
        .get(header::AUTHORIZATION)
        .and_then(|value| value.to_str().ok());
    TokenCheck::from_config(auth).caller(header).is_some()
}

#[derive(Debug, Default, Clone, Serialize, ToSchema)]
pub struct ClusterWorkers {
    pub busy: usize,
    pub idle: usize,
    /// Registered, not stopped, silent for longer than a lease.
    pub silent: usize,
}

async fn cluster_summary(core: &ServiceCore) -> ClusterWorkers {
    match cluster_workers(core).await {
        Ok(statuses) => {
            let summary = summarize(&statuses);
            ClusterWorkers {
                busy: summary.busy,
                idle: summary.idle,
                silent: summary.silent,
            }
        }
        Err(error) => {
            tracing::warn!(%error, "cannot list the cluster's workers");
            ClusterWorkers::default()
        }
    }
}

/// The process is alive.
#[utoipa::path(get, path = "/healthz", tag = "ops",
    responses((status = 200, description = "alive", body = HealthResponse)))]
pub async fn healthz() -> Json<HealthResponse> {
    Json(HealthResponse {
        status: "ok".to_string(),
    })
}

/// Whether the service can do its work: database and blob store reachable, GPU workers
/// available, models.
#[utoipa::path(get, path = "/readyz", tag = "ops",
    responses((status = 200, description = "ready; with a valid bearer token (or without tokens \
            configured) also the checks' details", body = ReadinessResponse),
        (status = 503, description = "not ready; with a valid bearer token (or without tokens \
            configured) `reasons` says why", body = ReadinessResponse)))]
pub async fn readyz(State(state): State<AppState>, headers: HeaderMap) -> impl IntoResponse {
    // Every check gets the same budget; one that cannot answer in it is reported as such,
    // with its last answer, and keeps running for the next probe.
    let until = std::time::Instant::now() + ANSWER_WITHIN;
    let probes = &state.readiness;
    let core = &state.core;
    let (database, blobs, cluster) = tokio::join!(
        probes.database.read(until, || {
            let database = core.database.clone();
            async move { database.ping().await.map_err(|error| error.to_string()) }
        }),
        probes.blobs.read(until, || {
            let store = core.blobs.clone();
            async move {
                match tokio::task::spawn_blocking(move || store.list_prefix("readyz-probe")).await {
                    Ok(Ok(_)) => Ok(()),
                    Ok(Err(error)) => Err(error.to_string()),
                    Err(error) => Err(format!("the check crashed: {error}")),
                }
            }
        }),
        probes.cluster.read(until, || {
            let core = core.clone();
            async move { cluster_summary(&core).await }
        }),
    );
    let database = reachability(database);
    let blobs = reachability(blobs);
    let cluster = match cluster {
        Reading::Fresh(cluster) => cluster,
        Reading::Pending { last, .. } => last.map(|last| last.value).unwrap_or_default(),
    };
    let workers = &state.workers;
    let adapters = if !workers.enabled {
        ReadinessCheck {
            ok: true,
            detail: "workers run in other processes".to_string(),
        }
    } else if workers.gpu_slots > 0 {
        ReadinessCheck {
            ok: true,
            detail: format!(
                "{} GPU worker slot(s) on {}",
                workers.gpu_slots,
                workers
                    .adapters
                    .iter()
                    .map(|adapter| format!("{} ({})", adapter.name, adapter.backend))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    } else {
        ReadinessCheck {
            ok: false,
            detail: if workers.problems.is_empty() {
                "no GPU worker slots".to_string()
            } else {
                workers.problems.join("; ")
            },
        }
    };
    let (models_ok, models_detail) = state.models.readiness();
    let models = ReadinessCheck {
        ok: models_ok,
        detail: models_detail,
    };
    let mut reasons = Vec::new();
    for (name, check) in [
        ("database", &database),
        ("blobs", &blobs),
        ("adapters", &adapters),
        ("models", &models),
    ] {
        if !check.ok {
            reasons.push(format!("{name}: {}", check.detail));
        }
    }
    let ready = reasons.is_empty();
    let body = if sees_details(&state, &headers) {
        ReadinessResponse {
            ready,
            reasons: Some(reasons),
            checks: Some(ReadinessChecks {
                database,
                blobs,
                adapters,
                models,
            }),
            adapters: Some(workers.adapters.clone()),
            cluster: Some(cluster),
        }
    } else {
        ReadinessResponse {
            ready,
            reasons: None,
            checks: None,
            adapters: None,
            cluster: None,
        }
    };
    let status = if ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    (status, Json(body))
}

/// A reachability check as `/readyz` reports it. One still running after the budget is not
/// ready ("no answer within ..."), with its last answer and how long ago that came.
fn reachability(reading: Reading<Result<(), String>>) -> ReadinessCheck {
    match reading {
        Reading::Fresh(Ok(())) => ReadinessCheck {
            ok: true,
            detail: "reachable".to_string(),
        },
        Reading::Fresh(Err(detail)) => ReadinessCheck { ok: false, detail },
        Reading::Pending { running_for, last } => {
            let last = match last {
                Some(last) => format!(
                    "; its last answer, {:.1} s ago: {}",
                    last.at.elapsed().as_secs_f64(),
                    match last.value {
                        Ok(()) => "reachable".to_string(),
                        Err(error) => error,
                    }
                ),
                None => String::new(),
            };
            ReadinessCheck {
                ok: false,
                detail: format!(
                    "no answer within {} ms (the check has run for {:.1} s){last}",
                    ANSWER_WITHIN.as_millis(),
                    running_for.as_secs_f64()
                ),
            }
        }
    }
}

/// Prometheus metrics in the text exposition format.
#[utoipa::path(get, path = "/metrics", tag = "ops",
    responses((status = 200, description = "Prometheus text format", body = String,
        content_type = "text/plain; version=0.0.4")))]
pub async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    refresh_queue_gauges(&state.core.database).await;
    refresh_cluster_gauges(&state.core).await;
    crate::metrics::refresh_process_metrics();
    state.metrics.run_upkeep();
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.metrics.render(),
    )
}
