//! Job-claim throughput and latency with 8 concurrent claimers: `SEGSPLAT_BENCH_CLAIM_JOBS` jobs
//! (default 400; the docs' figure uses 4000) are queued, then 8 claimers (as 8 worker slots
//! would) claim until the queue is empty. Reported per backend: claims per second, and the
//! latency of one claim (p50, p99, max), empty polls excluded. PostgreSQL runs when
//! `SEGSPLAT_TEST_POSTGRES_URL` names a server (`scripts/test_servers.sh` starts one), on a fresh
//! database; SQLite always runs, on a temporary file.
//! Run: `SEGSPLAT_BENCH_CLAIM_JOBS=4000 cargo bench --bench job_claims` (docs/benchmarks.md).

#[allow(dead_code)]
#[path = "../tests/common/postgres.rs"]
mod postgres;

use std::time::{Duration, Instant};

use segsplat_service::config::DatabaseConfig;
use segsplat_service::store::jobs::AttemptBounds;
use segsplat_service::store::scenes::SceneRecord;
use segsplat_service::store::{Caller, Database};

const CLAIMERS: usize = 8;
const KIND: &str = "bench";

fn percentile(sorted: &[Duration], fraction: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let index = ((sorted.len() - 1) as f64 * fraction).round() as usize;
    sorted[index].as_secs_f64() * 1000.0
}

async fn bench(
    name: &str,
    database: Database,
    jobs: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let scene = SceneRecord {
        id: "bench-scene".into(),
        name: "bench".into(),
        summary: serde_json::from_value(serde_json::json!({
            "format": "colmap", "frame_count": 1, "resolutions": [[4, 4]],
            "sparse_point_count": 0, "mask_levels": [],
        }))?,
        blob_prefix: "scenes/bench".into(),
        created_at_ms: 0,
        tenant: "default".into(),
    };
    database.insert_scene(&scene).await?;
    let bounds = AttemptBounds {
        max_attempts: 3,
        max_lease_expiries: 3,
    };
    let queued = Instant::now();
    for _ in 0..jobs {
        database
            .insert_job(
                &scene.id,
                KIND,
                &serde_json::json!({}),
                bounds,
                &Caller::system(),
            )
            .await?;
    }
    let queue_seconds = queued.elapsed().as_secs_f64();
    let started = Instant::now();
    let mut claimers = Vec::new();
    for claimer in 0..CLAIMERS {
        let database = database.clone();
        claimers.push(tokio::spawn(async move {
            let owner = format!("bench/{claimer}");
            let mut latencies = Vec::new();
            loop {
                let before = Instant::now();
                match database.claim_job(&owner, &[KIND], 600_000).await {
                    Ok(Some(_)) => latencies.push(before.elapsed()),
                    Ok(None) => return Ok(latencies),
                    Err(error) => return Err(error.to_string()),
                }
            }
        }));
    }
    let mut latencies = Vec::new();
    for claimer in claimers {
        latencies.extend(claimer.await??);
    }
    let seconds = started.elapsed().as_secs_f64();
    if latencies.len() != jobs {
        return Err(format!("{} claims for {jobs} jobs", latencies.len()).into());
    }
    latencies.sort();
    println!(
        "job_claims {name}: {jobs} jobs queued in {queue_seconds:.2} s; claimed by {CLAIMERS} \
         claimers in {seconds:.2} s = {:.0} claims/s; claim latency p50 {:.2} ms, p99 {:.2} ms, \
         max {:.2} ms",
        jobs as f64 / seconds,
        percentile(&latencies, 0.5),
        percentile(&latencies, 0.99),
        percentile(&latencies, 1.0),
    );
    database.close().await;
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let jobs: usize = std::env::var("SEGSPLAT_BENCH_CLAIM_JOBS")
        .ok()
        .and_then(|value| value.parse().ok())
        .unwrap_or(400);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(CLAIMERS)
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let dir = tempfile::tempdir()?;
        let sqlite = Database::open(&dir.path().join("claims.db")).await?;
        bench("sqlite", sqlite, jobs).await?;
        match std::env::var("SEGSPLAT_TEST_POSTGRES_URL") {
            Ok(server) => {
                let url = postgres::create_database(&server);
                let config = DatabaseConfig {
                    max_connections: CLAIMERS as u32 + 2,
                    ..DatabaseConfig::default()
                };
                let database = Database::open_postgres(&url, &config).await?;
                bench("postgres", database, jobs).await?;
            }
            Err(_) => println!(
                "job_claims postgres: no server (SEGSPLAT_TEST_POSTGRES_URL; \
                 scripts/test_servers.sh starts one); skipped"
            ),
        }
        Ok(())
    })
}
