//! The service core's use cases called directly, with no HTTP or gRPC in between: what the REST
//! handlers, the gRPC methods and the console all call. Scenes are created from an archive, jobs
//! queued, followed to their end through the event stream, and cancelled; failures come back as
//! typed errors naming the field at fault, and another tenant's resources look missing.

use std::io::Write;
use std::sync::Arc;
use std::time::Duration;

use futures::StreamExt;
use segsplat_scene::InputErrorClass;
use segsplat_service::store::Caller;
use segsplat_service::store::jobs::JobState;
use segsplat_service::usecases::jobs::{self, JobFailure};
use segsplat_service::usecases::scenes::{self, SceneFailure};
use serde_json::json;
use tokio_util::sync::CancellationToken;

use crate::common::archives::{colmap_zip, small_spec};
use crate::common::handlers::{STEPS_KIND, StepsHandler};
use crate::common::{TestService, test_config};

fn archive_file(bytes: &[u8]) -> tempfile::NamedTempFile {
    let mut file = tempfile::NamedTempFile::new().unwrap();
    file.write_all(bytes).unwrap();
    file
}

#[tokio::test]
async fn scenes_and_jobs_through_the_core_without_http() {
    let dir = tempfile::tempdir().unwrap();
    let handler = StepsHandler::default();
    let test = TestService::start(test_config(dir.path()), vec![Arc::new(handler.clone())]).await;
    let core = test.service.core().clone();
    let alice = Caller::tenant("alice");
    let bob = Caller::tenant("bob");

    // A dataset becomes a scene of the caller's tenant; garbage is rejected with its class.
    let scene = scenes::create_scene(
        &core,
        archive_file(&colmap_zip(small_spec())),
        Some("spheres".into()),
        alice.tenant.clone(),
    )
    .await
    .unwrap();
    assert_eq!(
        (scene.name.as_str(), scene.tenant.as_str()),
        ("spheres", "alice")
    );
    let rejected =
        scenes::create_scene(&core, archive_file(b"not an archive"), None, "alice".into())
            .await
            .unwrap_err();
    assert!(
        matches!(rejected, SceneFailure::Rejected { class, .. } if class != InputErrorClass::Internal),
        "{rejected:?}"
    );
    assert_eq!(scenes::list_scenes(&core, &alice).await.unwrap().len(), 1);
    assert!(scenes::list_scenes(&core, &bob).await.unwrap().is_empty());
    assert!(matches!(
        scenes::get_scene(&core, &bob, &scene.id).await,
        Err(SceneFailure::NotFound(_))
    ));

    // Bad job requests name the field at fault.
    let unknown = jobs::create_job(&core, &alice, &scene.id, "no_such_kind", &json!({}))
        .await
        .unwrap_err();
    assert!(
        matches!(&unknown, JobFailure::Invalid(message) if message.starts_with("kind:") && message.contains(STEPS_KIND)),
        "{unknown}"
    );
    let bad_config = jobs::create_job(&core, &alice, &scene.id, STEPS_KIND, &json!({"steps": "x"}))
        .await
        .unwrap_err();
    assert!(
        matches!(&bad_config, JobFailure::Invalid(message) if message.starts_with("config:")),
        "{bad_config}"
    );
    assert!(matches!(
        jobs::create_job(&core, &bob, &scene.id, STEPS_KIND, &json!({})).await,
        Err(JobFailure::SceneNotFound(_))
    ));
    assert!(matches!(
        jobs::list_jobs(&core, &alice, Some("sleeping")).await,
        Err(JobFailure::UnknownState(_))
    ));

    // A job runs to its end; its event stream replays everything and then closes.
    let job = jobs::create_job(&core, &alice, &scene.id, STEPS_KIND, &json!({"steps": 2}))
        .await
        .unwrap();
    assert_eq!(job.tenant, "alice");
    let events = jobs::follow_job_events(&core, &alice, &job.id, 0, CancellationToken::new())
        .await
        .unwrap();
    let events: Vec<_> = tokio::time::timeout(Duration::from_secs(20), events.collect())
        .await
        .expect("the event stream ends after the job's final state");
    let kinds: Vec<&str> = events.iter().map(|event| event.kind.as_str()).collect();
    assert!(kinds.contains(&"progress"), "{kinds:?}");
    assert_eq!(
        events.last().map(|event| event.payload["state"].clone()),
        Some(json!("succeeded")),
        "{events:?}"
    );
    let finished = jobs::get_job(&core, &alice, &job.id).await.unwrap();
    assert_eq!(finished.state, JobState::Succeeded);
    assert!(matches!(
        jobs::cancel_job(&core, &alice, &job.id).await,
        Err(JobFailure::AlreadyFinished { .. })
    ));
    assert!(matches!(
        jobs::follow_job_events(&core, &bob, &job.id, 0, CancellationToken::new()).await,
        Err(JobFailure::NotFound(_))
    ));
    assert_eq!(
        jobs::list_jobs(&core, &alice, Some("succeeded"))
            .await
            .unwrap()
            .len(),
        1
    );
    assert!(jobs::list_jobs(&core, &bob, None).await.unwrap().is_empty());

    // Deleting removes the scene and every file of it and of its jobs.
    assert!(matches!(
        scenes::delete_scene(&core, &bob, &scene.id).await,
        Err(SceneFailure::NotFound(_))
    ));
    scenes::delete_scene(&core, &alice, &scene.id)
        .await
        .unwrap();
    assert!(
        core.blobs
            .list_prefix(&scene.blob_prefix)
            .unwrap()
            .is_empty()
    );
    assert!(
        core.blobs
            .list_prefix(&format!("jobs/{}", job.id))
            .unwrap()
            .is_empty()
    );
    assert!(scenes::list_scenes(&core, &alice).await.unwrap().is_empty());
    test.service.shutdown().await;
}
