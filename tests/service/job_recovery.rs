//! The job queue when things go wrong: lease expiry and re-run by another worker, retries until
//! attempts are used up, restarts and graceful hand-back, torn checkpoints, crashes after
//! progress, and leftovers of stopped processes.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use segsplat_api::{ServiceBuilder, ServiceMode};
use segsplat_service::store::jobs::JobState;
use segsplat_service::store::{Caller, Database};
use serde_json::json;

use crate::common::handlers::{STEPS_KIND, StepsHandler};
use crate::common::{TestService, test_config};
use crate::jobs::{WAIT, parse_sse, start_with};

async fn start_worker_process(
    dir: &std::path::Path,
    handler: &StepsHandler,
) -> segsplat_api::RunningService {
    let mut config = test_config(dir);
    config.workers.cpu_slots = 1;
    ServiceBuilder::new(config)
        .mode(ServiceMode::WorkersOnly)
        .detect_gpus(false)
        .handler(Arc::new(handler.clone()))
        .start()
        .await
        .unwrap()
}

#[tokio::test]
async fn a_dead_workers_lease_expires_and_another_worker_reruns_the_job() {
    let dir = tempfile::tempdir().unwrap();
    let api_handler = StepsHandler::new();
    let api = start_with(dir.path(), 0, &api_handler).await;
    let scene_id = api.upload_test_scene().await;
    let job_id = api
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 3}))
        .await;
    // A worker claims the job and dies: it never heartbeats nor runs anything.
    let claimed = api
        .service
        .database()
        .claim_job("dead-worker/0", &[STEPS_KIND], 300)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(claimed.id, job_id);
    assert_eq!(claimed.attempts, 1);
    assert_eq!(api.job(&job_id).await["lease_owner"], "dead-worker/0");

    let worker_handler = StepsHandler::new();
    let worker = start_worker_process(dir.path(), &worker_handler).await;
    let job = api.wait_for_state(&job_id, "succeeded", WAIT).await;
    assert_eq!(job["attempts"], 2, "{job}");
    assert_eq!(worker_handler.stats.runs.load(Ordering::SeqCst), 1);
    assert_eq!(
        worker_handler.stats.steps_executed.load(Ordering::SeqCst),
        3
    );

    let events = api
        .service
        .database()
        .job_events_after(&job_id, 0, 100)
        .await
        .unwrap();
    let requeue = events
        .iter()
        .find(|event| {
            event.kind == "state"
                && event.payload["state"] == "queued"
                && event.payload["error"]
                    .as_str()
                    .is_some_and(|e| e.contains("lease expired"))
        })
        .expect("a re-queue event naming the expired lease");
    assert!(
        requeue.payload["error"]
            .as_str()
            .unwrap()
            .contains("dead-worker/0")
    );
    worker.shutdown().await;
    api.shutdown().await;
}

#[tokio::test]
async fn jobs_fail_with_the_reason_once_attempts_are_used_up() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let mut config = test_config(dir.path());
    config.jobs.max_attempts = 2;
    let service = TestService::start(config, vec![Arc::new(handler.clone())]).await;
    let scene_id = service.upload_test_scene().await;

    // The handler fails every attempt: retried once, then failed with its message.
    let failing = service
        .create_job(&scene_id, STEPS_KIND, json!({"fail_attempts": 10}))
        .await;
    let job = service.wait_for_state(&failing, "failed", WAIT).await;
    assert_eq!(job["attempts"], 2);
    assert_eq!(job["error"], "simulated failure on attempt 2");
    assert!(job["finished_at_ms"].is_i64());

    // One failure, then success.
    let flaky = service
        .create_job(&scene_id, STEPS_KIND, json!({"fail_attempts": 1}))
        .await;
    let job = service.wait_for_state(&flaky, "succeeded", WAIT).await;
    assert_eq!(job["attempts"], 2);
    assert!(job["error"].is_null());
    service.shutdown().await;

    // A lease that expires on the last attempt fails the job, naming the cause.
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.jobs.max_attempts = 1;
    config.workers.cpu_slots = 0;
    let service = TestService::start(config, vec![Arc::new(handler.clone())]).await;
    let scene_id = service.upload_test_scene().await;
    let job_id = service.create_job(&scene_id, STEPS_KIND, json!({})).await;
    service
        .service
        .database()
        .claim_job("dead-worker/0", &[STEPS_KIND], 200)
        .await
        .unwrap()
        .unwrap();
    let job = service.wait_for_state(&job_id, "failed", WAIT).await;
    let error = job["error"].as_str().unwrap();
    assert!(
        error.contains("lease expired") && error.contains("no attempts left"),
        "{error}"
    );
    service.shutdown().await;
}

#[tokio::test]
async fn a_restart_on_the_same_data_dir_resumes_queued_jobs() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let first = start_with(dir.path(), 0, &handler).await;
    let scene_id = first.upload_test_scene().await;
    let job_id = first
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 2}))
        .await;
    first.shutdown().await;

    let second = start_with(dir.path(), 1, &handler).await;
    let job = second.wait_for_state(&job_id, "succeeded", WAIT).await;
    assert_eq!(job["attempts"], 1);
    assert_eq!(handler.stats.steps_executed.load(Ordering::SeqCst), 2);
    second.shutdown().await;
}

/// Runs a `steps`-step job on a service in `dir` until it reports `step`, then shuts the service
/// down (the job is handed back); returns the job and the handler that ran it.
async fn shut_down_past_step(
    dir: &std::path::Path,
    steps: u64,
    step: u64,
) -> (String, StepsHandler) {
    let handler = StepsHandler::new();
    let service = start_with(dir, 1, &handler).await;
    let scene_id = service.upload_test_scene().await;
    let job_id = service
        .create_job(
            &scene_id,
            STEPS_KIND,
            json!({"steps": steps, "step_ms": 25}),
        )
        .await;
    let started = std::time::Instant::now();
    loop {
        let job = service.job(&job_id).await;
        if job["progress"]["step"].as_u64().unwrap_or(0) >= step {
            break;
        }
        assert!(started.elapsed() < WAIT, "no progress: {job}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    service.shutdown().await;
    (job_id, handler)
}

#[tokio::test]
async fn shutdown_hands_running_jobs_back_and_the_next_run_resumes_from_the_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let steps = 40;
    let (job_id, first_handler) = shut_down_past_step(dir.path(), steps, 3).await;

    let database = Database::connect(&test_config(dir.path())).await.unwrap();
    let job = database
        .get_job(&job_id, &Caller::system())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(job.state, JobState::Queued);
    assert_eq!(job.lease_owner, None);
    assert_eq!(job.attempts, 0, "a handed-back attempt is not counted");
    database.close().await;
    let done_before = first_handler.stats.steps_executed.load(Ordering::SeqCst);
    assert!(done_before >= 3 && done_before < steps);

    let second_handler = StepsHandler::new();
    let second = start_with(dir.path(), 1, &second_handler).await;
    let job = second.wait_for_state(&job_id, "succeeded", WAIT).await;
    assert_eq!(job["attempts"], 1);
    let done_after = second_handler.stats.steps_executed.load(Ordering::SeqCst);
    assert_eq!(
        done_before + done_after,
        steps,
        "resumed from the checkpoint, no step twice"
    );
    second.shutdown().await;
}

/// A worker killed in the middle of an upload can leave a torn newest checkpoint behind (s3rver
/// keeps short uploads): the next attempt says so, resumes from the generation before it, and
/// redoes only the steps in between.
#[tokio::test]
async fn a_torn_newest_checkpoint_costs_its_steps_not_the_job() {
    let dir = tempfile::tempdir().unwrap();
    let steps = 30;
    let (job_id, first_handler) = shut_down_past_step(dir.path(), steps, 4).await;
    let done_before = first_handler.stats.steps_executed.load(Ordering::SeqCst);

    // The handler checkpoints every step: the newest two generations are kept, older ones go.
    let checkpoints = dir.path().join(format!("blobs/jobs/{job_id}/checkpoints"));
    let mut generations = crate::common::files_under(&checkpoints);
    generations.sort();
    assert_eq!(generations.len(), 2, "{generations:?}");
    let newest = checkpoints.join(&generations[1]);
    let bytes = std::fs::read(&newest).unwrap();
    std::fs::write(&newest, &bytes[..3]).unwrap();

    let second_handler = StepsHandler::new();
    let second = start_with(dir.path(), 1, &second_handler).await;
    let job = second.wait_for_state(&job_id, "succeeded", WAIT).await;
    assert_eq!(job["attempts"], 1, "{job}");
    let done_after = second_handler.stats.steps_executed.load(Ordering::SeqCst);
    assert_eq!(
        done_before + done_after,
        steps + 1,
        "resumed from the generation before the torn one: one step redone"
    );
    let (status, events) = second.get_bytes(&format!("/v1/jobs/{job_id}/events")).await;
    assert_eq!(status, 200);
    let warnings: Vec<serde_json::Value> = parse_sse(&String::from_utf8_lossy(&events))
        .into_iter()
        .filter(|(name, _)| name == "warning")
        .map(|(_, data)| data["payload"].clone())
        .collect();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!(warnings[0]["stage"], "resume");
    let message = warnings[0]["message"].as_str().unwrap_or_default();
    assert!(
        message.contains("unusable") && message.contains("3 bytes"),
        "{message}"
    );
    second.shutdown().await;
}

/// Claims the job as a worker that saves a checkpoint and then dies, and waits until the reaper
/// has dealt with the expired lease.
async fn crash_after_a_checkpoint(service: &TestService, job_id: &str, worker: &str) {
    let database = service.service.database();
    let claimed = database
        .claim_job(worker, &[STEPS_KIND], 100)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(claimed.id, job_id);
    assert!(database.record_checkpoint(job_id, worker).await.unwrap());
    let started = std::time::Instant::now();
    while database
        .get_job(job_id, &Caller::system())
        .await
        .unwrap()
        .unwrap()
        .state
        == JobState::Running
    {
        assert!(started.elapsed() < WAIT, "the lease never expired");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test]
async fn crashes_after_progress_are_not_counted_as_attempts_but_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let mut config = test_config(dir.path());
    config.jobs.max_attempts = 3;
    config.jobs.max_lease_expiries = 5;
    config.workers.cpu_slots = 0;
    let service = TestService::start(config, vec![Arc::new(handler.clone())]).await;
    let scene_id = service.upload_test_scene().await;

    // Three process crashes, each after a new checkpoint: still queued, no attempt used.
    let job_id = service.create_job(&scene_id, STEPS_KIND, json!({})).await;
    for crash in 0..3 {
        crash_after_a_checkpoint(&service, &job_id, &format!("crashing-{crash}/0")).await;
        let job = service.job(&job_id).await;
        assert_eq!(job["state"], "queued", "{job}");
        assert_eq!(job["attempts"], 0, "{job}");
        assert_eq!(job["lease_expiries"], crash + 1, "{job}");
        assert!(
            job["error"]
                .as_str()
                .is_some_and(|error| error.contains("not counted as an attempt")),
            "{job}"
        );
    }

    // A job that crashes its worker every time still ends, naming the bound.
    for crash in 3..5 {
        crash_after_a_checkpoint(&service, &job_id, &format!("crashing-{crash}/0")).await;
    }
    let job = service.job(&job_id).await;
    assert_eq!(job["state"], "failed", "{job}");
    assert!(job["finished_at_ms"].is_i64(), "{job}");
    let error = job["error"].as_str().unwrap();
    assert!(error.contains("jobs.max_lease_expiries = 5"), "{error}");

    // A running handler's checkpoints are noted on the job.
    let worker = start_worker_process(dir.path(), &handler).await;
    let job_id = service
        .create_job(&scene_id, STEPS_KIND, json!({"steps": 200, "step_ms": 20}))
        .await;
    let started = std::time::Instant::now();
    loop {
        let job = service
            .service
            .database()
            .get_job(&job_id, &Caller::system())
            .await
            .unwrap()
            .unwrap();
        if job.state == JobState::Running && job.checkpointed_this_attempt {
            break;
        }
        assert!(started.elapsed() < WAIT, "checkpoint never noted: {job:?}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    service
        .post_json(&format!("/v1/jobs/{job_id}/cancel"), json!({}))
        .await;
    service.wait_for_state(&job_id, "cancelled", WAIT).await;
    worker.shutdown().await;
    service.shutdown().await;
}

#[tokio::test]
async fn a_restart_takes_back_its_own_and_dead_local_processes_jobs_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::new();
    let hour_ms = 3_600_000;
    let api = start_with(dir.path(), 0, &handler).await;
    let scene_id = api.upload_test_scene().await;
    let mut jobs = Vec::new();
    for _ in 0..3 {
        jobs.push(api.create_job(&scene_id, STEPS_KIND, json!({})).await);
    }
    api.shutdown().await;
    // Processes that held the leases and are gone; the leases would last an hour. Claims take
    // the oldest queued job, so the owners go in creation order.
    let database = Database::connect(&test_config(dir.path())).await.unwrap();
    // A pid above the kernel's limit: a process on this host that is certainly gone.
    let dead_local = format!(
        "{}-pid4294967-0badf00d/0",
        segsplat_service::jobs::host_name()
    );
    let owners = ["box-1/0", dead_local.as_str(), "other-host-pid7-0badf00d/0"];
    for (job_id, owner) in jobs.iter().zip(owners) {
        let claimed = database
            .claim_job(owner, &[STEPS_KIND], hour_ms)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(&claimed.id, job_id);
    }
    database.close().await;
    let (own, local, foreign) = (&jobs[0], &jobs[1], &jobs[2]);

    let mut config = test_config(dir.path());
    config.workers.instance_id = Some("box-1".to_string());
    let service = TestService::start(config, vec![Arc::new(handler.clone())]).await;
    for job_id in [own, local] {
        let job = service.wait_for_state(job_id, "succeeded", WAIT).await;
        assert_eq!(job["attempts"], 2, "{job}");
    }
    // Another host's lease is left to run out.
    let job = service.job(foreign).await;
    assert_eq!(job["state"], "running", "{job}");
    assert_eq!(job["lease_owner"], "other-host-pid7-0badf00d/0", "{job}");
    service.shutdown().await;
}

#[tokio::test]
async fn a_succeeded_jobs_checkpoints_are_deleted_unless_kept() {
    for keep in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        let handler = StepsHandler::new();
        let mut config = test_config(dir.path());
        config.jobs.keep_final_checkpoint = keep;
        let service = TestService::start(config, vec![Arc::new(handler.clone())]).await;
        let scene_id = service.upload_test_scene().await;
        let job_id = service.create_job(&scene_id, STEPS_KIND, json!({})).await;
        service.wait_for_state(&job_id, "succeeded", WAIT).await;
        // The deletion follows the recorded outcome; give it a moment.
        let checkpoints = dir.path().join(format!("blobs/jobs/{job_id}/checkpoints"));
        let started = std::time::Instant::now();
        while !keep && !crate::common::files_under(&checkpoints).is_empty() {
            assert!(started.elapsed() < WAIT, "checkpoints kept");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
        assert_eq!(
            crate::common::files_under(&checkpoints).is_empty(),
            !keep,
            "keep_final_checkpoint = {keep}: {:?}",
            crate::common::files_under(&checkpoints)
        );
        service.shutdown().await;
    }
}

#[tokio::test]
async fn a_start_reclaims_leftovers_of_stopped_processes_and_nothing_live() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join("tmp");
    let checkpoints = dir.path().join("blobs/jobs/j1/checkpoints");
    std::fs::create_dir_all(&tmp).unwrap();
    std::fs::create_dir_all(&checkpoints).unwrap();
    let host = segsplat_service::jobs::host_name();
    // A pid above the kernel's limit: a process on this host that is certainly gone.
    let dead = format!("{host}-pid4294967");
    let live = format!("{host}-pid{}", std::process::id());
    let write = |path: std::path::PathBuf| {
        std::fs::write(&path, b"partial").unwrap();
        path
    };
    let unpack = tmp.join(format!("unpack-{dead}-Ab12Cd"));
    std::fs::create_dir_all(unpack.join("images")).unwrap();
    write(unpack.join("images/0.png"));
    let removed = [
        write(tmp.join(format!("upload-{dead}-Xy34Zw"))),
        unpack,
        {
            let job_dir = tmp.join("job-0190aaaa-bbbb-7ccc-8ddd-eeeeffff0000-1");
            std::fs::create_dir_all(&job_dir).unwrap();
            job_dir
        },
        write(checkpoints.join(format!(".step.segsplat-tmp-{dead}-0123abcd"))),
        {
            // A worker's scene fetch cut off by its death.
            let fetch = dir
                .path()
                .join(format!("cache/scenes/.abc.segsplat-tmp-{dead}-0123abcd"));
            std::fs::create_dir_all(fetch.join("images")).unwrap();
            write(fetch.join("images/0.png"));
            fetch
        },
        {
            // Another host's, untouched for two days.
            let old = write(tmp.join("upload-elsewhere-pid7-Qw12Er"));
            let two_days_ago = std::time::SystemTime::now() - Duration::from_secs(2 * 86_400);
            std::fs::File::options()
                .write(true)
                .open(&old)
                .unwrap()
                .set_modified(two_days_ago)
                .unwrap();
            old
        },
    ];
    let kept = [
        write(tmp.join(format!("upload-{live}-Lv12Ab"))),
        write(tmp.join("unpack-elsewhere-pid7-Fr12Sh")),
        write(checkpoints.join(".step.segsplat-tmp-elsewhere-pid7-0123abcd")),
        write(checkpoints.join("step")),
        {
            let copy = dir.path().join("cache/scenes/abc");
            std::fs::create_dir_all(&copy).unwrap();
            write(copy.join(".complete"))
        },
    ];

    let handler = StepsHandler::new();
    let service = start_with(dir.path(), 0, &handler).await;
    for path in &removed {
        assert!(!path.exists(), "left behind: {}", path.display());
    }
    for path in &kept {
        assert!(path.exists(), "removed: {}", path.display());
    }
    service.shutdown().await;
}
