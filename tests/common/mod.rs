//! Shared helpers for the service integration tests: a real server on ephemeral ports, a
//! CPU-only test job kind, and synthetic dataset archives.
#![allow(dead_code)]

pub mod archives;
pub mod handlers;
#[path = "../models_support/mod.rs"]
pub mod models_support;
pub mod object_store;
pub mod postgres;
pub mod s3rver;
pub mod segsplat_bin;
pub mod zip_bomb;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use segsplat_api::{RunningService, ServiceBuilder};
use segsplat_service::config::Config;
use segsplat_service::jobs::JobHandler;

pub use models_support::tiny_models_dir;

/// A test config: ephemeral ports, fast leases and polling, one CPU worker slot, no GPU. The
/// database is the SQLite file in `data_dir`, or a fresh PostgreSQL database when
/// `SEGSPLAT_TEST_BACKEND=postgres` ([`postgres`]).
pub fn test_config(data_dir: &Path) -> Config {
    let mut config = Config {
        data_dir: data_dir.to_path_buf(),
        http_addr: "127.0.0.1:0".parse().unwrap(),
        grpc_addr: "127.0.0.1:0".parse().unwrap(),
        ..Config::default()
    };
    config.jobs.lease_secs = 0.8;
    config.jobs.heartbeat_secs = 0.1;
    config.jobs.poll_interval_ms = 50;
    config.jobs.max_attempts = 3;
    config.workers.cpu_slots = 1;
    config.workers.ops_addr = "127.0.0.1:0".parse().unwrap();
    config.limits.max_upload_bytes = 4 << 20;
    if postgres::backend_is_postgres() {
        config.database.url = Some(postgres::database_for_data_dir(data_dir));
    }
    config
}

pub struct TestService {
    pub service: RunningService,
    pub base_url: String,
    pub client: reqwest::Client,
}

impl TestService {
    pub async fn start(config: Config, handlers: Vec<Arc<dyn JobHandler>>) -> TestService {
        config.validate().unwrap();
        let mut builder = ServiceBuilder::new(config).detect_gpus(false);
        for handler in handlers {
            builder = builder.handler(handler);
        }
        let service = builder.start().await.unwrap();
        let base_url = format!("http://{}", service.http_addr().unwrap());
        TestService {
            service,
            base_url,
            client: reqwest::Client::new(),
        }
    }

    /// A service with the training job kinds on a GPU worker (lavapipe in CI): `configure`
    /// adjusts the test config first. `None` (skip) without a GPU when `SEGSPLAT_SKIP_GPU_TESTS`
    /// is set; without that variable a missing adapter fails.
    pub async fn start_on_gpu(
        data_dir: &Path,
        configure: impl FnOnce(&mut Config),
    ) -> Option<TestService> {
        if !gpu_or_skip("this test") {
            return None;
        }
        let mut config = test_config(data_dir);
        config.workers.cpu_slots = 0;
        config.jobs.lease_secs = 30.0;
        config.jobs.heartbeat_secs = 1.0;
        configure(&mut config);
        let service = ServiceBuilder::new(config)
            .handler(Arc::new(segsplat_service::job_kinds::ReconstructHandler))
            .handler(Arc::new(
                segsplat_service::job_kinds::SegmentThenSplatHandler,
            ))
            .start()
            .await
            .unwrap();
        let base_url = format!("http://{}", service.http_addr().unwrap());
        Some(TestService {
            service,
            base_url,
            client: reqwest::Client::new(),
        })
    }

    /// [`Self::start_on_gpu`] with `models.dir` set to the tiny stand-in models (CLIP
    /// embeddings, text queries, SAM masks). `None` (skip) also when ONNX Runtime is missing and
    /// `SEGSPLAT_SKIP_ORT_TESTS=1`; without that variable a missing library fails.
    pub async fn start_with_tiny_models(data_dir: &Path) -> Option<TestService> {
        models_support::runtime()?;
        Self::start_on_gpu(data_dir, |config| {
            config.models.dir = Some(tiny_models_dir())
        })
        .await
    }

    /// A gRPC client of this service's `SceneQuery`.
    pub async fn grpc(
        &self,
    ) -> segsplat_api::proto::scene_query_client::SceneQueryClient<tonic::transport::Channel> {
        let addr = self.service.grpc_addr().unwrap();
        let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
            .unwrap()
            .connect()
            .await
            .unwrap();
        segsplat_api::proto::scene_query_client::SceneQueryClient::new(channel)
    }

    /// GET returning the status and raw body.
    pub async fn get_bytes(&self, path: &str) -> (u16, Vec<u8>) {
        let response = self.client.get(self.url(path)).send().await.unwrap();
        let status = response.status().as_u16();
        (status, response.bytes().await.unwrap().to_vec())
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base_url, path)
    }

    pub async fn get_json(&self, path: &str) -> (u16, serde_json::Value) {
        let response = self.client.get(self.url(path)).send().await.unwrap();
        let status = response.status().as_u16();
        (
            status,
            response.json().await.unwrap_or(serde_json::Value::Null),
        )
    }

    pub async fn post_json(&self, path: &str, body: serde_json::Value) -> (u16, serde_json::Value) {
        let response = self
            .client
            .post(self.url(path))
            .json(&body)
            .send()
            .await
            .unwrap();
        let status = response.status().as_u16();
        (
            status,
            response.json().await.unwrap_or(serde_json::Value::Null),
        )
    }

    /// Uploads an archive as the raw body.
    pub async fn upload(&self, bytes: Vec<u8>, content_type: &str) -> (u16, serde_json::Value) {
        let response = self
            .client
            .post(self.url("/v1/scenes"))
            .header("content-type", content_type)
            .body(bytes)
            .send()
            .await
            .unwrap();
        let status = response.status().as_u16();
        (
            status,
            response.json().await.unwrap_or(serde_json::Value::Null),
        )
    }

    /// Uploads a small valid COLMAP scene and returns its id.
    pub async fn upload_test_scene(&self) -> String {
        let (status, body) = self
            .upload(
                archives::colmap_zip(archives::small_spec()),
                "application/zip",
            )
            .await;
        assert_eq!(status, 201, "{body}");
        body["id"].as_str().unwrap().to_string()
    }

    pub async fn create_job(
        &self,
        scene_id: &str,
        kind: &str,
        config: serde_json::Value,
    ) -> String {
        let (status, body) = self
            .post_json(
                &format!("/v1/scenes/{scene_id}/jobs"),
                serde_json::json!({"kind": kind, "config": config}),
            )
            .await;
        assert_eq!(status, 201, "{body}");
        body["id"].as_str().unwrap().to_string()
    }

    pub async fn job(&self, job_id: &str) -> serde_json::Value {
        let (status, body) = self.get_json(&format!("/v1/jobs/{job_id}")).await;
        assert_eq!(status, 200, "{body}");
        body
    }

    /// Polls until the job is in `state` (panics after `timeout`).
    pub async fn wait_for_state(
        &self,
        job_id: &str,
        state: &str,
        timeout: Duration,
    ) -> serde_json::Value {
        let started = Instant::now();
        loop {
            let job = self.job(job_id).await;
            if job["state"] == state {
                return job;
            }
            assert!(
                started.elapsed() < timeout,
                "job {job_id} did not reach {state} within {timeout:?}; last: {job}"
            );
            tokio::time::sleep(Duration::from_millis(25)).await;
        }
    }

    pub async fn shutdown(self) {
        self.service.shutdown().await;
    }
}

/// Whether a GPU adapter opens; `false` (skip, with the reason) without one when
/// `SEGSPLAT_SKIP_GPU_TESTS` is set; without that variable a missing adapter fails.
pub fn gpu_or_skip(test: &str) -> bool {
    if segsplat_gpu::GpuContext::new_default().is_ok() {
        return true;
    }
    if std::env::var("SEGSPLAT_SKIP_GPU_TESTS").is_ok() {
        eprintln!("skipping {test}: no GPU adapter");
        return false;
    }
    panic!("no GPU adapter (lavapipe is installed by scripts/bootstrap.sh)");
}

/// Every file under `dir`, relative, sorted (empty when `dir` does not exist).
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                out.push(path.strip_prefix(root).unwrap().to_path_buf());
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Entries (files or folders) directly under `dir`.
pub fn entries_in(dir: &Path) -> Vec<PathBuf> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|entries| entries.flatten().map(|entry| entry.path()).collect())
        .unwrap_or_default();
    entries.sort();
    entries
}
