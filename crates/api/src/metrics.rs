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
    let response =
        segsplat_service::usecases::observe::called_from("rest", next.run(request)).await;
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
/// `rate()` and alert expressions work from the first scrape. Job outcomes get a series per
/// registered job kind (`kinds`) and outcome: before issue 41 they were registered once under
/// `kind="none"`, a kind no job has, which showed up in every breakdown by kind.
pub fn register_zero_series(kinds: &[&str]) {
    describe_families();
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
        for kind in kinds {
            metrics::counter!("segsplat_job_outcomes_total", "kind" => kind.to_string(),
                "outcome" => outcome)
            .increment(0);
        }
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
        "segsplat_worker_slots",
        "segsplat_workers_busy",
        "segsplat_workers_idle",
    ] {
        metrics::gauge!(gauge).increment(0.0);
    }
}

/// Every metric family the service exports, with its type and help text: the one list the
/// `# HELP` lines come from, that docs/service.md documents, and that `tests/metrics_families.rs`
/// checks a running service against. Process metrics (`process_*`) come from `metrics-process`.
pub const FAMILIES: &[(&str, MetricType, &str)] = &[
    (
        "segsplat_http_requests_total",
        MetricType::Counter,
        "REST requests answered, by route template, method and status.",
    ),
    (
        "segsplat_http_request_duration_seconds",
        MetricType::Histogram,
        "Time to answer a REST request, by route template and method.",
    ),
    (
        "segsplat_grpc_requests_total",
        MetricType::Counter,
        "gRPC calls answered, by method and status code (a stream counts when its headers go out).",
    ),
    (
        "segsplat_grpc_request_duration_seconds",
        MetricType::Histogram,
        "Time to a gRPC call's response headers (for a stream, its first message), by method.",
    ),
    (
        "segsplat_jobs",
        MetricType::Gauge,
        "Jobs in the database by state (the queue's depth), read at each scrape.",
    ),
    (
        "segsplat_job_outcomes_total",
        MetricType::Counter,
        "Job attempts finished, by job kind and outcome.",
    ),
    (
        "segsplat_job_attempt_seconds",
        MetricType::Histogram,
        "Duration of a job attempt, by job kind.",
    ),
    (
        "segsplat_job_leases_expired_total",
        MetricType::Counter,
        "Running jobs taken back because their worker stopped renewing the lease.",
    ),
    (
        "segsplat_job_steps_total",
        MetricType::Counter,
        "Steps done by jobs, by worker and stage; rate() is steps per second per worker.",
    ),
    (
        "segsplat_worker_slots",
        MetricType::Gauge,
        "Worker slots (concurrent jobs) in this process.",
    ),
    (
        "segsplat_workers_busy",
        MetricType::Gauge,
        "Worker slots of this process running a job.",
    ),
    (
        "segsplat_workers_idle",
        MetricType::Gauge,
        "Worker slots of this process waiting for a job.",
    ),
    (
        "segsplat_cluster_workers",
        MetricType::Gauge,
        "Worker slots of every process on this database, by state (busy, idle, or silent: no \
         heartbeat for a lease).",
    ),
    (
        "segsplat_scene_uploads_total",
        MetricType::Counter,
        "Scene uploads, by outcome (stored or rejected).",
    ),
    (
        "segsplat_scene_cache_bytes",
        MetricType::Gauge,
        "GPU memory held by the serving cache of trained scenes.",
    ),
    (
        "segsplat_scene_cache_scenes",
        MetricType::Gauge,
        "Trained scenes held by the serving cache.",
    ),
    (
        "segsplat_query_seconds",
        MetricType::Histogram,
        "Time to score a text query (masks excluded), by API (rest, grpc, internal) and outcome.",
    ),
    (
        "segsplat_mask_render_seconds",
        MetricType::Histogram,
        "Time to render masks, by API (rest, grpc, internal) and outcome.",
    ),
    (
        "segsplat_build_info",
        MetricType::Gauge,
        "Always 1: this build's version and git commit, and this process's first GPU adapter.",
    ),
];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MetricType {
    Counter,
    Gauge,
    Histogram,
}

/// Gives every family its `# HELP` text and starts the process metrics (`process_*`).
fn describe_families() {
    for (name, kind, help) in FAMILIES {
        match kind {
            MetricType::Counter => metrics::describe_counter!(*name, *help),
            MetricType::Gauge => metrics::describe_gauge!(*name, *help),
            MetricType::Histogram => metrics::describe_histogram!(*name, *help),
        }
    }
    process_collector().describe();
}

fn process_collector() -> &'static metrics_process::Collector {
    static COLLECTOR: OnceLock<metrics_process::Collector> = OnceLock::new();
    COLLECTOR.get_or_init(metrics_process::Collector::default)
}

/// Reads the process's CPU, memory, threads and file descriptors, for the scrape at hand.
pub fn refresh_process_metrics() {
    process_collector().collect();
}

/// `segsplat_build_info{version, git_commit, adapter} 1`.
pub fn record_build_info(adapter: &str) {
    metrics::gauge!("segsplat_build_info", "version" => env!("CARGO_PKG_VERSION"),
        "git_commit" => env!("SEGSPLAT_GIT_COMMIT"), "adapter" => adapter.to_string())
    .set(1.0);
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
