//! `segsplat serve` and SIGTERM, as Kubernetes stops a pod: the process ends, with exit status
//! 0, well within the grace period, whatever stage its job is in (docs/deploy.md, "Stopping a
//! worker").

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::archives::{colmap_files, zip_of};
use common::postgres::free_port;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::SyntheticSpec;
use serde_json::json;

/// How long a stopping process may take: the 15 s issue 39 asks for, well inside Kubernetes'
/// grace periods (30 s by default, 120 s for the workers in deploy/kubernetes).
const STOP_WITHIN: Duration = Duration::from_secs(15);
const WAIT: Duration = Duration::from_secs(300);

/// A `segsplat serve` process; killed (SIGKILL) when dropped, so a failing test leaves none.
struct Serve {
    child: Child,
    base_url: String,
    /// Everything it logged (stdout, where the logger writes), line by line.
    log: mpsc::Receiver<String>,
    _data_dir: tempfile::TempDir,
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Serve {
    /// Starts `segsplat serve` on a fresh data dir with one GPU slot (lavapipe in CI), `env`
    /// added, and returns once it answers `/healthz`. `None` (skip) without a GPU adapter when
    /// `SEGSPLAT_SKIP_GPU_TESTS` is set.
    async fn start(env: &[(&str, &str)]) -> Option<Serve> {
        if segsplat_gpu::GpuContext::new_default().is_err() {
            if std::env::var("SEGSPLAT_SKIP_GPU_TESTS").is_ok() {
                eprintln!("skipping: no GPU adapter");
                return None;
            }
            panic!("no GPU adapter (lavapipe is installed by scripts/bootstrap.sh)");
        }
        let data_dir = tempfile::tempdir().unwrap();
        let http_port = free_port();
        let mut child = Command::new(common::segsplat_bin::segsplat_bin())
            .arg("serve")
            .arg("--data-dir")
            .arg(data_dir.path())
            .arg("--http")
            .arg(format!("127.0.0.1:{http_port}"))
            .arg("--grpc")
            .arg(format!("127.0.0.1:{}", free_port()))
            .env_clear()
            .env("PATH", std::env::var("PATH").unwrap_or_default())
            .env("XDG_RUNTIME_DIR", "/tmp")
            .env("SEGSPLAT_LOG__LEVEL", "info")
            .env("SEGSPLAT_JOBS__HEARTBEAT_SECS", "0.5")
            .env("SEGSPLAT_JOBS__POLL_INTERVAL_MS", "100")
            .envs(env.iter().copied())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (lines, log) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if lines.send(line).is_err() {
                    break;
                }
            }
        });
        let serve = Serve {
            child,
            base_url: format!("http://127.0.0.1:{http_port}"),
            log,
            _data_dir: data_dir,
        };
        let client = reqwest::Client::new();
        let started = Instant::now();
        while client
            .get(format!("{}/healthz", serve.base_url))
            .send()
            .await
            .is_err()
        {
            assert!(started.elapsed() < WAIT, "segsplat serve never answered");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        Some(serve)
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base_url)
    }

    /// Uploads the synthetic spheres at `spec` (a COLMAP zip) and returns the scene id.
    async fn upload(&self, client: &reqwest::Client, spec: SyntheticSpec) -> String {
        let archive = zip_of(&colmap_files(spec, ColmapEncoding::Binary));
        let request = client.post(self.url("/v1/scenes"));
        created_id(
            request
                .header("content-type", "application/zip")
                .body(archive),
        )
        .await
    }

    /// Queues `job` (`{"kind", "config"}`) on the scene and returns the job id.
    async fn queue(
        &self,
        client: &reqwest::Client,
        scene_id: &str,
        job: serde_json::Value,
    ) -> String {
        created_id(
            client
                .post(self.url(&format!("/v1/scenes/{scene_id}/jobs")))
                .json(&job),
        )
        .await
    }

    /// Polls the job until `done` says yes of it; panics after [`WAIT`] or when it finished.
    async fn wait_for_job(
        &self,
        client: &reqwest::Client,
        job_id: &str,
        done: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let started = Instant::now();
        loop {
            let job: serde_json::Value = client
                .get(self.url(&format!("/v1/jobs/{job_id}")))
                .send()
                .await
                .unwrap()
                .json()
                .await
                .unwrap();
            if done(&job) {
                return job;
            }
            assert!(started.elapsed() < WAIT, "job never got there: {job}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Sends SIGTERM and waits for the process to end: its exit status, how long it took, and
    /// what it logged.
    fn terminate(mut self) -> (ExitStatus, Duration, String) {
        let sent = Instant::now();
        let status = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .expect("running kill");
        assert!(status.success());
        // Waits past the bound (a stuck process is then reported with its time), not forever.
        let exited = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            if sent.elapsed() > STOP_WITHIN * 8 {
                let _ = self.child.kill();
                break self.child.wait().unwrap();
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let took = sent.elapsed();
        let log: Vec<String> = self.log.try_iter().collect();
        (exited, took, log.join("\n"))
    }
}

/// A started `serve` with `job` (`{"kind", "config"}`) queued on the synthetic spheres at
/// `spec`: the serve, its client, the scene id and the job id. `None` where [`Serve::start`]
/// skips.
async fn serve_with_job(
    spec: SyntheticSpec,
    job: serde_json::Value,
) -> Option<(Serve, reqwest::Client, String, String)> {
    let serve = Serve::start(&[]).await?;
    let client = reqwest::Client::new();
    let scene_id = serve.upload(&client, spec).await;
    let job_id = serve.queue(&client, &scene_id, job).await;
    Some((serve, client, scene_id, job_id))
}

/// Sends `request`, which must answer 201, and returns the created resource's `id`.
async fn created_id(request: reqwest::RequestBuilder) -> String {
    let response = request.send().await.unwrap();
    let status = response.status();
    let body: serde_json::Value = response.json().await.unwrap_or_default();
    assert_eq!(status, 201, "{body}");
    body["id"].as_str().unwrap().to_string()
}

/// A `segment_then_splat` job generating classical masks (a stage of many views, one blocking
/// call each) is handed back and the process ends within [`STOP_WITHIN`] of SIGTERM. Before the
/// fix the stage ignored the stop: the worker waited its grace, logged "segsplat stopped", and
/// the process then kept segmenting until the stage ended.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_in_the_segment_stage_ends_the_process_within_the_grace() {
    // Enough views that the stage takes far longer than the bound on this machine.
    let spec = SyntheticSpec {
        frame_count: 48,
        width: 640,
        height: 480,
        ..SyntheticSpec::default()
    };
    let job = json!({"kind": "segment_then_splat", "config": {"masks": "classical", "steps": 20}});
    let Some((serve, client, _, job_id)) = serve_with_job(spec, job).await else {
        return;
    };
    let job = serve
        .wait_for_job(&client, &job_id, |job| {
            job["progress"]["stage"] == "segment" && job["progress"]["step"].as_u64() >= Some(1)
        })
        .await;
    let total_views = job["progress"]["total_steps"].as_u64().unwrap();
    let (status, took, log) = serve.terminate();
    println!("segment stage (1 of {total_views} views done): SIGTERM to exit {took:?}");
    assert!(log.contains("segsplat stopped"), "{log}");
    assert!(
        log.contains("handed_back"),
        "the job was not handed back: {log}"
    );
    assert!(took < STOP_WITHIN, "took {took:?} to stop: {log}");
    assert!(status.success(), "{status}: {log}");
}

/// Where `needle` first appears in `log`; panics naming it when it does not.
fn position(log: &str, needle: &str) -> usize {
    log.find(needle)
        .unwrap_or_else(|| panic!("the log never says {needle:?}:\n{log}"))
}

/// A `serve` that has trained a scene and rendered a mask from it (so both the workers' GPU
/// context and the mask renderer's hold buffers and pipelines) exits 0 on SIGTERM within the
/// grace, having released the mask renderer's GPU (cached scenes, renderer, then its device)
/// and then the workers' devices before "segsplat stopped": nothing on the GPU is left for the
/// driver's exit handlers or a thread still dropping it (issue 39, defect 5: on NVIDIA's Vulkan
/// driver the process died with SIGSEGV after "segsplat stopped"; lavapipe does not crash, so
/// the order is asserted from the log).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_after_training_and_rendering_releases_the_gpu_and_exits_0() {
    // The dataset's own masks: no segmenter to wait for.
    let spec = SyntheticSpec {
        frame_count: 6,
        width: 64,
        height: 48,
        with_masks: Some(segsplat_scene::Level::ALL.to_vec()),
        ..SyntheticSpec::default()
    };
    let job = json!({"kind": "segment_then_splat", "config": {"steps": 20, "checkpoint_every": 0}});
    let Some((serve, client, scene_id, job_id)) = serve_with_job(spec, job).await else {
        return;
    };
    let job = serve
        .wait_for_job(&client, &job_id, |job| {
            matches!(job["state"].as_str(), Some("succeeded" | "failed"))
        })
        .await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let mask = client
        .get(serve.url(&format!(
            "/v1/scenes/{scene_id}/objects/small/1/mask.png?frame_index=0"
        )))
        .send()
        .await
        .unwrap();
    assert_eq!(mask.status(), 200);
    assert!(!mask.bytes().await.unwrap().is_empty());

    let (status, took, log) = serve.terminate();
    println!("trained and rendered: SIGTERM to exit {took:?}");
    let renderer = position(&log, "mask rendering GPU released");
    let workers = position(&log, "worker GPU released");
    let stopped = position(&log, "segsplat stopped");
    assert!(
        renderer < workers && workers < stopped,
        "released out of order:\n{log}"
    );
    assert!(took < STOP_WITHIN, "took {took:?} to stop: {log}");
    assert_eq!(status.code(), Some(0), "{status}: {log}");
}
