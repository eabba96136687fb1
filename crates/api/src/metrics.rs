//! Prometheus metrics: one process-wide recorder, request counters and latency histograms by
//! route and status, and queue-depth gauges refreshed at each scrape.

use std::sync::OnceLock;
use std::time::Instant;

use axum::extract::{MatchedPath, Request};
use axum::middleware::Next;
use axum::response::Response;
use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle};

use segsplat_service::core::ServiceCore;
use segsplat_service::store::Database;
use segsplat_service::store::jobs::JobState;
use segsplat_service::usecases::workers::{cluster_workers, summarize};

/// Latency buckets in seconds, from fast API calls to long uploads.
const LATENCY_BUCKETS_SECS: [f64; 14] = [
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 10.0, 60.0, 600.0,
];

static HANDLE: OnceLock<Option<PrometheusHandle>> = OnceLock::new();

/// The process's Prometheus recorder, installed on first use. Later calls (a second service in
/// the same test process) share it. `None` when another recorder was installed first.
pub fn prometheus_handle() -> Option<PrometheusHandle> {
    HANDLE
        .get_or_init(|| {
            let builder = PrometheusBuilder::new()
                .set_buckets(&LATENCY_BUCKETS_SECS)
                .ok()?;
            let recorder = builder.build_recorder();
            let handle = recorder.handle();
            metrics::set_global_recorder(recorder).ok()?;
            Some(handle)
        })
        .clone()
}

/// Counts requests and records their latency, labelled by route template (not raw path, to keep
/// label cardinality bounded), method and status.
pub async fn track_requests(request: Request, next: Next) -> Response {
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |path| path.as_str().to_string());
    let method = request.method().to_string();
    let started = Instant::now();
    let response = next.run(request).await;
    let status = response.status().as_u16().to_string();
    metrics::counter!("segsplat_http_requests_total", "route" => route.clone(),
        "method" => method.clone(), "status" => status)
    .increment(1);
    metrics::histogram!("segsplat_http_request_duration_seconds", "route" => route,
        "method" => method)
    .record(started.elapsed().as_secs_f64());
    response
}

/// Registers the series dashboards and alerts need before anything happened, at zero: a
/// counter nobody incremented yet (no lease has expired) is exported as 0, not missing, so
/// `rate()` and alert expressions work from the first scrape.
pub fn register_zero_series() {
    metrics::counter!("segsplat_job_leases_expired_total").increment(0);
    metrics::gauge!("segsplat_scene_cache_bytes").increment(0.0);
    metrics::gauge!("segsplat_scene_cache_scenes").increment(0.0);
    for outcome in [
        "succeeded",
        "failed",
        "retry",
        "cancelled",
        "handed_back",
        "lease_lost",
    ] {
        metrics::counter!("segsplat_job_outcomes_total", "kind" => "none", "outcome" => outcome)
            .increment(0);
    }
    for outcome in ["stored", "rejected"] {
        metrics::counter!("segsplat_scene_uploads_total", "outcome" => outcome).increment(0);
    }
    for state in JobState::ALL {
        metrics::gauge!("segsplat_jobs", "state" => state.as_str()).increment(0.0);
    }
    for state in ["busy", "idle", "silent"] {
        metrics::gauge!("segsplat_cluster_workers", "state" => state).increment(0.0);
    }
    for gauge in [
        "segsplat_workers_total",
        "segsplat_workers_busy",
        "segsplat_workers_idle",
    ] {
        metrics::gauge!(gauge).increment(0.0);
    }
}

/// Sets `segsplat_cluster_workers{state=busy|idle|silent}`: worker slots of every process on
/// this database, where `segsplat_workers_*` count this process's own.
pub async fn refresh_cluster_gauges(core: &ServiceCore) {
    match cluster_workers(core).await {
        Ok(statuses) => {
            let summary = summarize(&statuses);
            for (state, count) in [
                ("busy", summary.busy),
                ("idle", summary.idle),
                ("silent", summary.silent),
            ] {
                metrics::gauge!("segsplat_cluster_workers", "state" => state).set(count as f64);
            }
        }
        Err(error) => tracing::warn!(%error, "cannot count the cluster's workers for metrics"),
    }
}

/// Sets `segsplat_jobs{state=...}` from the database.
pub async fn refresh_queue_gauges(database: &Database) {
    match database.job_counts_by_state().await {
        Ok(counts) => {
            for (state, count) in counts {
                metrics::gauge!("segsplat_jobs", "state" => state.as_str()).set(count as f64);
            }
        }
        Err(error) => tracing::warn!(%error, "cannot count jobs for metrics"),
    }
}
