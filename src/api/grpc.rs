//! gRPC `segsplat.v1.SceneQuery`: scene, job and object reads, and the unary text `Query` (objects
//! and scores; masks for a view come with the mask renderer). The streaming query and
//! `RenderMask` answer `UNIMPLEMENTED` until the Segment-then-Splat pipeline provides them.

use std::pin::Pin;
use std::sync::Arc;
use std::time::Instant;

use futures::Stream;
use tonic::{Request, Response, Status};

use super::query::{QueryFailure, run_query};
use crate::language::{DEFAULT_RELEVANCY_THRESHOLD, Granularity, QueryOptions, SharedTextEncoder};
use crate::proto;
use crate::proto::scene_query_server::SceneQuery;
use crate::scene::Level;
use crate::store::jobs::{JobRecord, JobState};
use crate::store::objects::ObjectRecord;
use crate::store::scenes::SceneRecord;
use crate::store::{Database, StoreError};

const PIPELINE_PENDING: &str = "arrives with the Segment-then-Splat pipeline";

#[derive(Clone)]
pub struct SceneQueryService {
    database: Database,
    text_encoder: Arc<SharedTextEncoder>,
}

impl SceneQueryService {
    pub fn new(database: Database, text_encoder: Arc<SharedTextEncoder>) -> Self {
        Self {
            database,
            text_encoder,
        }
    }
}

fn query_failure_status(failure: QueryFailure) -> Status {
    let message = failure.to_string();
    match failure {
        QueryFailure::BadOptions(_) | QueryFailure::EmptyText => Status::invalid_argument(message),
        QueryFailure::SceneNotFound(_) => Status::not_found(message),
        QueryFailure::NoObjects(_) | QueryFailure::NoEmbeddings { .. } => {
            Status::failed_precondition(message)
        }
        QueryFailure::NoTextEncoder(_) => Status::unavailable(message),
        QueryFailure::Store(_) | QueryFailure::Encoding(_) => {
            tracing::error!(%message, "gRPC query failed");
            Status::internal(message)
        }
    }
}

fn granularity_from_proto(value: i32) -> Result<Granularity, Status> {
    match proto::Granularity::try_from(value) {
        Ok(proto::Granularity::Auto) => Ok(Granularity::Auto),
        Ok(proto::Granularity::Small) => Ok(Granularity::Small),
        Ok(proto::Granularity::Middle) => Ok(Granularity::Middle),
        Ok(proto::Granularity::Large) => Ok(Granularity::Large),
        Err(_) => Err(Status::invalid_argument(format!(
            "granularity: unknown value {value}"
        ))),
    }
}

fn internal(error: StoreError) -> Status {
    tracing::error!(%error, "gRPC request failed");
    Status::internal(error.to_string())
}

fn job_state_to_proto(state: JobState) -> proto::JobState {
    match state {
        JobState::Queued => proto::JobState::Queued,
        JobState::Running => proto::JobState::Running,
        JobState::Succeeded => proto::JobState::Succeeded,
        JobState::Failed => proto::JobState::Failed,
        JobState::Cancelled => proto::JobState::Cancelled,
    }
}

fn level_to_proto(level: Level) -> proto::Level {
    match level {
        Level::Small => proto::Level::Small,
        Level::Middle => proto::Level::Middle,
        Level::Large => proto::Level::Large,
    }
}

fn level_from_proto(level: proto::Level) -> Option<Level> {
    match level {
        proto::Level::Unspecified => None,
        proto::Level::Small => Some(Level::Small),
        proto::Level::Middle => Some(Level::Middle),
        proto::Level::Large => Some(Level::Large),
    }
}

fn vec3(values: [f32; 3]) -> proto::Vec3 {
    proto::Vec3 {
        x: values[0],
        y: values[1],
        z: values[2],
    }
}

fn progress_to_proto(progress: &serde_json::Value) -> Option<proto::Progress> {
    let parsed: crate::jobs::Progress = serde_json::from_value(progress.clone()).ok()?;
    Some(proto::Progress {
        stage: parsed.stage,
        step: parsed.step,
        total_steps: parsed.total_steps,
        metrics: parsed.metrics.into_iter().collect(),
        eta_secs: parsed.eta_secs,
    })
}

fn job_to_proto(job: JobRecord) -> proto::Job {
    proto::Job {
        state: job_state_to_proto(job.state) as i32,
        progress: job.progress.as_ref().and_then(progress_to_proto),
        config_json: job.config.to_string(),
        id: job.id,
        scene_id: job.scene_id,
        kind: job.kind,
        attempts: job.attempts,
        max_attempts: job.max_attempts,
        error: job.error,
        created_at_ms: job.created_at_ms,
        updated_at_ms: job.updated_at_ms,
        cancel_requested: job.cancel_requested,
    }
}

fn scene_to_proto(scene: SceneRecord) -> proto::Scene {
    proto::Scene {
        format: serde_json::to_value(scene.summary.format)
            .ok()
            .and_then(|value| value.as_str().map(str::to_string))
            .unwrap_or_default(),
        frame_count: scene.summary.frame_count,
        sparse_point_count: scene.summary.sparse_point_count,
        has_masks: !scene.summary.mask_levels.is_empty(),
        id: scene.id,
        name: scene.name,
        created_at_ms: scene.created_at_ms,
    }
}

fn object_to_proto(object: ObjectRecord) -> proto::ObjectInfo {
    proto::ObjectInfo {
        object_id: object.object_id,
        level: level_to_proto(object.level) as i32,
        gaussian_count: object.gaussian_count,
        centroid: Some(vec3(object.centroid)),
        bounds: Some(proto::Bounds3 {
            min: Some(vec3(object.bounds_min)),
            max: Some(vec3(object.bounds_max)),
        }),
        mean_color: Some(vec3(object.mean_color)),
    }
}

type StreamQueryStream =
    Pin<Box<dyn Stream<Item = Result<proto::StreamQueryResponse, Status>> + Send + 'static>>;

#[tonic::async_trait]
impl SceneQuery for SceneQueryService {
    async fn query(
        &self,
        request: Request<proto::QueryRequest>,
    ) -> Result<Response<proto::QueryResponse>, Status> {
        let started = Instant::now();
        let request = request.into_inner();
        let options = QueryOptions {
            granularity: granularity_from_proto(request.granularity)?,
            top_k: (request.top_k.max(1)) as usize,
            threshold: request.min_score.unwrap_or(DEFAULT_RELEVANCY_THRESHOLD),
        };
        let outcome = run_query(
            &self.database,
            &self.text_encoder,
            &request.scene_id,
            &request.text,
            options,
        )
        .await
        .map_err(query_failure_status)?;
        // `request.view` asks for masks; they need the GPU mask renderer and its scene cache,
        // which are not in the service yet, so matches carry objects and scores with no masks.
        let matches = outcome
            .matches
            .into_iter()
            .map(|found| proto::QueryMatch {
                object: Some(object_to_proto(found.object)),
                score: found.score,
                relevancy: found.relevancy,
                mask: None,
                visible_mask: None,
            })
            .collect();
        Ok(Response::new(proto::QueryResponse {
            matches,
            no_match: !outcome.matched,
            model_id: outcome.model_id,
            latency_ms: started.elapsed().as_secs_f64() * 1000.0,
        }))
    }

    type StreamQueryStream = StreamQueryStream;

    async fn stream_query(
        &self,
        _request: Request<tonic::Streaming<proto::StreamQueryRequest>>,
    ) -> Result<Response<Self::StreamQueryStream>, Status> {
        Err(Status::unimplemented(format!(
            "StreamQuery {PIPELINE_PENDING}"
        )))
    }

    async fn list_objects(
        &self,
        request: Request<proto::ListObjectsRequest>,
    ) -> Result<Response<proto::ListObjectsResponse>, Status> {
        let request = request.into_inner();
        let level = proto::Level::try_from(request.level).map_err(|_| {
            Status::invalid_argument(format!("level: unknown value {}", request.level))
        })?;
        if self
            .database
            .get_scene(&request.scene_id)
            .await
            .map_err(internal)?
            .is_none()
        {
            return Err(Status::not_found(format!(
                "scene {} not found",
                request.scene_id
            )));
        }
        let objects = self
            .database
            .list_objects(&request.scene_id, level_from_proto(level))
            .await
            .map_err(internal)?;
        Ok(Response::new(proto::ListObjectsResponse {
            objects: objects.into_iter().map(object_to_proto).collect(),
        }))
    }

    async fn render_mask(
        &self,
        _request: Request<proto::RenderMaskRequest>,
    ) -> Result<Response<proto::RenderMaskResponse>, Status> {
        Err(Status::unimplemented(format!(
            "RenderMask {PIPELINE_PENDING}"
        )))
    }

    async fn get_job(
        &self,
        request: Request<proto::GetJobRequest>,
    ) -> Result<Response<proto::Job>, Status> {
        let job_id = request.into_inner().job_id;
        let job = self
            .database
            .get_job(&job_id)
            .await
            .map_err(internal)?
            .ok_or_else(|| Status::not_found(format!("job {job_id} not found")))?;
        Ok(Response::new(job_to_proto(job)))
    }

    async fn get_scene(
        &self,
        request: Request<proto::GetSceneRequest>,
    ) -> Result<Response<proto::Scene>, Status> {
        let scene_id = request.into_inner().scene_id;
        let scene = self
            .database
            .get_scene(&scene_id)
            .await
            .map_err(internal)?
            .ok_or_else(|| Status::not_found(format!("scene {scene_id} not found")))?;
        Ok(Response::new(scene_to_proto(scene)))
    }

    async fn list_scenes(
        &self,
        _request: Request<proto::ListScenesRequest>,
    ) -> Result<Response<proto::ListScenesResponse>, Status> {
        let scenes = self.database.list_scenes().await.map_err(internal)?;
        Ok(Response::new(proto::ListScenesResponse {
            scenes: scenes.into_iter().map(scene_to_proto).collect(),
        }))
    }
}
