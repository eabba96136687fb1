//! A host that crashes again and again between checkpoints does not fail a job that trains on
//! each life: `segsplat serve` (a real process, on the GPU, SQLite in its data dir) is killed with
//! SIGKILL a few seconds into each resume, three times, while a `reconstruct` job that saves no
//! checkpoint before its end trains. Steps trained since the claim count as progress, like a
//! checkpoint: each loss of the lease is a `lease_expiries`, not an attempt.

mod common;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::archives::{colmap_files, zip_of};
use common::postgres::free_port;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::SyntheticSpec;
use serde_json::json;

const WAIT: Duration = Duration::from_secs(60);
const CRASHES: u64 = 3;

/// `segsplat serve` on `data_dir`, killed (SIGKILL) when dropped.
struct Serve(Child);

impl Serve {
    fn start(data_dir: &std::path::Path, http_port: u16) -> Serve {
        let child = Command::new(common::segsplat_bin::segsplat_bin())
            .arg("serve")
            .arg("--data-dir")
            .arg(data_dir)
            .env("SEGSPLAT_HTTP_ADDR", format!("127.0.0.1:{http_port}"))
            .env("SEGSPLAT_GRPC_ADDR", format!("127.0.0.1:{}", free_port()))
            // The same name in every life: a restart takes its previous life's job back at once.
            .env("SEGSPLAT_WORKERS__INSTANCE_ID", "crashing-host")
            .env("SEGSPLAT_WORKERS__CPU_SLOTS", "0")
            .env("SEGSPLAT_LOG__LEVEL", "warn")
            .env("XDG_RUNTIME_DIR", "/tmp")
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        Serve(child)
    }

    fn kill(mut self) {
        self.0.kill().unwrap();
        self.0.wait().unwrap();
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

async fn fetch_job(client: &reqwest::Client, api: &str, job_id: &str) -> serde_json::Value {
    let started = Instant::now();
    loop {
        // The process may still be starting.
        if let Ok(response) = client.get(format!("{api}/v1/jobs/{job_id}")).send().await
            && response.status().is_success()
        {
            return response.json().await.unwrap();
        }
        assert!(started.elapsed() < WAIT, "{api} never answered");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn steps_between_crashes_are_progress_not_attempts() {
    let test = "steps_between_crashes_are_progress_not_attempts";
    if !common::gpu_or_skip(test) {
        return;
    }
    let data_dir = tempfile::tempdir().unwrap();
    let http_port = free_port();
    let api = format!("http://127.0.0.1:{http_port}");
    let client = reqwest::Client::new();
    let mut serve = Serve::start(data_dir.path(), http_port);
    let spec = SyntheticSpec {
        frame_count: 4,
        width: 32,
        height: 24,
        ..SyntheticSpec::default()
    };
    let archive = zip_of(&colmap_files(spec, ColmapEncoding::Binary));
    let started = Instant::now();
    let scene: serde_json::Value = loop {
        if let Ok(response) = client
            .post(format!("{api}/v1/scenes"))
            .header("content-type", "application/zip")
            .body(archive.clone())
            .send()
            .await
        {
            assert_eq!(response.status(), 201);
            break response.json().await.unwrap();
        }
        assert!(started.elapsed() < WAIT, "serve never answered");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    let response = client
        .post(format!(
            "{api}/v1/scenes/{}/jobs",
            scene["id"].as_str().unwrap()
        ))
        // No checkpoint before the end (checkpoint_every 0): every crash loses its steps.
        .json(&json!({"kind": "reconstruct",
                      "config": {"steps": 1000000, "checkpoint_every": 0}}))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), 201);
    let created: serde_json::Value = response.json().await.unwrap();
    let job_id = created["id"].as_str().unwrap().to_string();

    for crash in 1..=CRASHES {
        // Kill the host once this life has trained and reported some steps past its first
        // report.
        let mut first_step = None;
        let started = Instant::now();
        loop {
            let job = fetch_job(&client, &api, &job_id).await;
            assert_ne!(job["state"], "failed", "crash {crash}: {job}");
            let step = job["progress"]["step"].as_u64();
            if job["state"] == "running" && job["progress"]["stage"] == "train" {
                match (first_step, step) {
                    (None, Some(step)) => first_step = Some(step),
                    (Some(first), Some(step)) if step >= first + 20 => break,
                    _ => {}
                }
            }
            assert!(
                started.elapsed() < WAIT,
                "crash {crash}: no training: {job}"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        serve.kill();
        serve = Serve::start(data_dir.path(), http_port);
        // The restart takes the job back at start and claims it again.
        let started = Instant::now();
        let job = loop {
            let job = fetch_job(&client, &api, &job_id).await;
            let claims =
                job["attempts"].as_u64().unwrap_or(0) + job["lease_expiries"].as_u64().unwrap_or(0);
            if (job["state"] == "running" && claims == crash + 1) || job["state"] == "failed" {
                break job;
            }
            assert!(
                started.elapsed() < WAIT,
                "crash {crash}: not taken back: {job}"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        };
        assert_ne!(job["state"], "failed", "crash {crash}: {job}");
        assert_eq!(
            job["attempts"], 1,
            "crash {crash}: a crash after steps is no attempt: {job}"
        );
        assert_eq!(job["lease_expiries"], crash, "{job}");
    }
    let response = client
        .post(format!("{api}/v1/jobs/{job_id}/cancel"))
        .send()
        .await
        .unwrap();
    assert!(response.status().is_success(), "{}", response.status());
    serve.kill();
}
