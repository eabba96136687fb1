//! gRPC `segsplat.v1.SceneQuery`: scene, job and object reads; the text `Query`, unary and
//! streamed (robots send poses, get masks per pose), with masks rendered from the GPU scene
//! cache when a view is given; and `RenderMask` for one object.

use std::pin::Pin;
use std::time::Instant;

use futures::{Stream, StreamExt};
use tonic::{Request, Response, Status};

use super::auth::grpc_caller;
use crate::grpc_convert::{
    camera_to_proto, granularity_from_proto, internal, job_failure_status, job_to_proto,
    level_from_proto, mask_format_from_proto, mask_to_proto, object_to_proto, query_failure_status,
    scene_failure_status, scene_to_proto, serve_failure_status, time_from_proto, view_from_proto,
};
use crate::proto;
use crate::proto::scene_query_server::SceneQuery;
use segsplat_service::core::ServiceCore;
use segsplat_service::store::Caller;
use segsplat_service::usecases::jobs;
use segsplat_service::usecases::objects::{ListObjectsError, list_objects};
use segsplat_service::usecases::observe::called_from;
use segsplat_service::usecases::query::{
    MaskRequest, QueryError, QueryRequest as CoreQuery, query_with_masks,
};
use segsplat_service::usecases::scenes;
use segsplat_vision::language::{DEFAULT_RELEVANCY_THRESHOLD, QueryOptions};

/// Replies a stream query may have waiting before the client reads them.
const STREAM_BUFFER: usize = 4;
/// Messages of one stream answered at once. Renders share the GPU (one at a time), so more
/// would only queue there; two lets one answer encode and send while the next renders, and a
/// third lets the next message be read and parsed meanwhile.
const STREAM_PIPELINE: usize = 3;

#[derive(Clone)]
pub struct SceneQueryService {
    core: ServiceCore,
}

impl SceneQueryService {
    pub fn new(core: ServiceCore) -> Self {
        Self { core }
    }

    /// One query with optional masks: the core of `Query` and of each `StreamQuery` message.
    async fn answer(
        &self,
        query: QueryParts,
        caller: &Caller,
    ) -> Result<proto::QueryResponse, Status> {
        let started = Instant::now();
        let options = QueryOptions {
            granularity: granularity_from_proto(query.granularity)?,
            top_k: (query.top_k.max(1)) as usize,
            threshold: query.min_score.unwrap_or(DEFAULT_RELEVANCY_THRESHOLD),
        };
        let format = mask_format_from_proto(query.mask_encoding)?;
        let view = match (&query.view, format) {
            (Some(view), Some(_)) => Some(view_from_proto(view)?),
            (None, Some(_)) => {
                return Err(Status::invalid_argument(
                    "view: masks were asked for (mask_encoding) but no view was given",
                ));
            }
            (_, None) => None,
        };
        let time = time_from_proto(query.time.or(query.view.as_ref().and_then(|v| v.time)))?;
        let masks = match (view, format) {
            (Some(view), Some(format)) => Some(MaskRequest {
                view,
                format,
                visible: query.visible_only,
            }),
            _ => None,
        };
        let answer = query_with_masks(
            &self.core.database,
            &self.core.text_encoder,
            &self.core.serving,
            caller,
            CoreQuery {
                scene_id: query.scene_id,
                text: query.text,
                options,
                time,
                masks,
            },
        )
        .await
        .map_err(|error| match error {
            QueryError::Query(failure) => query_failure_status(failure),
            QueryError::Serve(failure) => serve_failure_status(failure),
        })?;
        let matches = answer
            .objects
            .into_iter()
            .map(|found| proto::QueryMatch {
                mask: found.mask.as_ref().map(|mask| mask_to_proto(mask, true)),
                visible_mask: found
                    .visible_mask
                    .as_ref()
                    .map(|mask| mask_to_proto(mask, false)),
                object: Some(object_to_proto(found.object)),
                score: found.score,
                relevancy: found.relevancy,
            })
            .collect();
        Ok(proto::QueryResponse {
            matches,
            no_match: !answer.matched,
            model_id: answer.model_id,
            latency_ms: started.elapsed().as_secs_f64() * 1000.0,
        })
    }
}

/// What one query needs, from a `QueryRequest` or the running state of a stream.
#[derive(Debug, Clone, Default)]
struct QueryParts {
    scene_id: String,
    text: String,
    granularity: i32,
    top_k: u32,
    min_score: Option<f32>,
    view: Option<proto::View>,
    /// Dynamic scenes: the answer's time (else the view's).
    time: Option<f64>,
    mask_encoding: i32,
    visible_only: bool,
}

impl QueryParts {
    /// Folds one stream message in: scene, text, granularity and top_k carry over when a
    /// message leaves them empty; the view and mask encoding are per message.
    fn update(&mut self, message: proto::StreamQueryRequest) {
        if !message.scene_id.is_empty() {
            self.scene_id = message.scene_id;
        }
        if !message.text.is_empty() {
            self.text = message.text;
        }
        if message.granularity != 0 {
            self.granularity = message.granularity;
        }
        if message.top_k != 0 {
            self.top_k = message.top_k;
        }
        self.view = message.view.map(|pose| proto::View {
            source: Some(proto::view::Source::Pose(pose)),
            time: message.time,
            max_side: None,
        });
        self.time = message.time;
        self.mask_encoding = message.mask_encoding;
    }
}

/// The work of one `StreamQuery`: reads messages, answers up to [`STREAM_PIPELINE`] of them at
/// once, and sends the answers in the order the messages came.
async fn answer_stream(
    service: SceneQueryService,
    caller: Caller,
    mut incoming: tonic::Streaming<proto::StreamQueryRequest>,
    replies: tokio::sync::mpsc::Sender<Result<proto::StreamQueryResponse, Status>>,
) {
    let mut parts = QueryParts::default();
    let mut answering = futures::stream::FuturesOrdered::new();
    let mut reading = true;
    loop {
        tokio::select! {
            // Answers first: a finished one frees a place in the pipeline.
            biased;
            Some(reply) = answering.next(), if !answering.is_empty() => {
                let failed = Result::is_err(&reply);
                if replies.send(reply).await.is_err() || failed {
                    break;
                }
            }
            message = incoming.message(), if reading && answering.len() < STREAM_PIPELINE => {
                match message {
                    Ok(Some(message)) => {
                        let sequence = message.sequence;
                        parts.update(message);
                        let (service, caller, parts) = (service.clone(), caller.clone(), parts.clone());
                        answering.push_back(async move {
                            service.answer(parts, &caller).await.map(|response| {
                                proto::StreamQueryResponse {
                                    sequence,
                                    response: Some(response),
                                }
                            })
                        });
                    }
                    Ok(None) => reading = false,
                    Err(status) => {
                        tracing::debug!(%status, "stream query client went away");
                        break;
                    }
                }
            }
            else => break,
        }
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
        let caller = grpc_caller(&request)?;
        let request = request.into_inner();
        let parts = QueryParts {
            scene_id: request.scene_id,
            text: request.text,
            granularity: request.granularity,
            top_k: request.top_k,
            min_score: request.min_score,
            time: request.time,
            view: request.view,
            mask_encoding: request.mask_encoding,
            visible_only: request.visible_only,
        };
        Ok(Response::new(self.answer(parts, &caller).await?))
    }

    type StreamQueryStream = StreamQueryStream;

    /// Answers each incoming message in order, echoing its `sequence`. Up to
    /// [`STREAM_PIPELINE`] messages are answered at once: the next pose's render starts while
    /// the previous answer is still encoding or waiting to be sent, and reading the client's
    /// next message never waits on an answer. A message that fails (say, a bad pose) ends the
    /// stream with that error, after the answers before it, like a unary call would.
    async fn stream_query(
        &self,
        request: Request<tonic::Streaming<proto::StreamQueryRequest>>,
    ) -> Result<Response<Self::StreamQueryStream>, Status> {
        let caller = grpc_caller(&request)?;
        let incoming = request.into_inner();
        let service = self.clone();
        let (replies, receiver) = tokio::sync::mpsc::channel(STREAM_BUFFER);
        // The stream's answers are rendered in this task, outside the request's own future:
        // label their latencies as gRPC here.
        tokio::spawn(called_from(
            "grpc",
            answer_stream(service, caller, incoming, replies),
        ));
        Ok(Response::new(Box::pin(
            tokio_stream::wrappers::ReceiverStream::new(receiver),
        )))
    }

    async fn list_objects(
        &self,
        request: Request<proto::ListObjectsRequest>,
    ) -> Result<Response<proto::ListObjectsResponse>, Status> {
        let caller = grpc_caller(&request)?;
        let request = request.into_inner();
        let level = proto::Level::try_from(request.level).map_err(|_| {
            Status::invalid_argument(format!("level: unknown value {}", request.level))
        })?;
        let objects = list_objects(
            &self.core.database,
            &self.core.serving,
            &caller,
            &request.scene_id,
            level_from_proto(level),
            time_from_proto(request.time)?,
        )
        .await
        .map_err(|error| match error {
            ListObjectsError::SceneNotFound(_) => Status::not_found(error.to_string()),
            ListObjectsError::Store(store) => internal(store),
            ListObjectsError::Serve(failure) => serve_failure_status(failure),
        })?;
        Ok(Response::new(proto::ListObjectsResponse {
            objects: objects.into_iter().map(object_to_proto).collect(),
        }))
    }

    async fn render_mask(
        &self,
        request: Request<proto::RenderMaskRequest>,
    ) -> Result<Response<proto::RenderMaskResponse>, Status> {
        let caller = grpc_caller(&request)?;
        let request = request.into_inner();
        let level = proto::Level::try_from(request.level)
            .ok()
            .and_then(level_from_proto)
            .ok_or_else(|| {
                Status::invalid_argument(format!(
                    "level: {} is not small, middle or large",
                    request.level
                ))
            })?;
        let view = request
            .view
            .as_ref()
            .ok_or_else(|| Status::invalid_argument("view: required"))
            .and_then(view_from_proto)?;
        // The reply is the mask, so "no mask" (NONE, also proto3's default) cannot be honoured.
        let format = mask_format_from_proto(request.mask_encoding)?.ok_or_else(|| {
            Status::invalid_argument(
                "mask_encoding: RenderMask answers with a mask; ask for MASK_ENCODING_PNG or \
                 MASK_ENCODING_COCO_RLE (MASK_ENCODING_NONE is for Query and StreamQuery)",
            )
        })?;
        let time = time_from_proto(request.view.as_ref().and_then(|v| v.time))?;
        let masks = self
            .core
            .serving
            .render_masks(
                &request.scene_id,
                &caller,
                view,
                time,
                vec![(level, request.object_id)],
                request.visible_only,
                format,
            )
            .await
            .map_err(serve_failure_status)?;
        let first = masks
            .first()
            .ok_or_else(|| Status::internal("no mask rendered"))?;
        let mask = match (&first.visible_mask, request.visible_only) {
            (Some(visible), true) => mask_to_proto(visible, false),
            _ => mask_to_proto(&first.mask, true),
        };
        Ok(Response::new(proto::RenderMaskResponse {
            mask: Some(mask),
        }))
    }

    async fn get_job(
        &self,
        request: Request<proto::GetJobRequest>,
    ) -> Result<Response<proto::Job>, Status> {
        let caller = grpc_caller(&request)?;
        let job_id = request.into_inner().job_id;
        let job = jobs::get_job(&self.core, &caller, &job_id)
            .await
            .map_err(job_failure_status)?;
        Ok(Response::new(job_to_proto(job)))
    }

    async fn get_scene(
        &self,
        request: Request<proto::GetSceneRequest>,
    ) -> Result<Response<proto::Scene>, Status> {
        let caller = grpc_caller(&request)?;
        let scene_id = request.into_inner().scene_id;
        let scene = scenes::get_scene(&self.core, &caller, &scene_id)
            .await
            .map_err(scene_failure_status)?;
        Ok(Response::new(scene_to_proto(scene)))
    }

    async fn list_scenes(
        &self,
        request: Request<proto::ListScenesRequest>,
    ) -> Result<Response<proto::ListScenesResponse>, Status> {
        let caller = grpc_caller(&request)?;
        let records = scenes::list_scenes(&self.core, &caller)
            .await
            .map_err(scene_failure_status)?;
        Ok(Response::new(proto::ListScenesResponse {
            scenes: records.into_iter().map(scene_to_proto).collect(),
        }))
    }

    async fn list_cameras(
        &self,
        request: Request<proto::ListCamerasRequest>,
    ) -> Result<Response<proto::ListCamerasResponse>, Status> {
        let caller = grpc_caller(&request)?;
        let scene_id = request.into_inner().scene_id;
        let cameras = self
            .core
            .serving
            .cameras(&scene_id, &caller)
            .await
            .map_err(serve_failure_status)?;
        Ok(Response::new(proto::ListCamerasResponse {
            cameras: cameras
                .into_iter()
                .enumerate()
                .map(|(index, camera)| camera_to_proto(index, camera))
                .collect(),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stream_messages_carry_their_time_with_and_without_a_pose() {
        let mut parts = QueryParts::default();
        parts.update(proto::StreamQueryRequest {
            scene_id: "scene".into(),
            text: "mug".into(),
            view: Some(proto::PoseView::default()),
            time: Some(0.25),
            ..Default::default()
        });
        assert_eq!(parts.time, Some(0.25));
        assert_eq!(parts.view.as_ref().and_then(|view| view.time), Some(0.25));
        // A later message without a pose still moves the answer's time; text and scene stay.
        parts.update(proto::StreamQueryRequest {
            time: Some(0.75),
            ..Default::default()
        });
        assert_eq!((parts.time, parts.view.is_none()), (Some(0.75), true));
        assert_eq!(
            (parts.scene_id.as_str(), parts.text.as_str()),
            ("scene", "mug")
        );
        assert!(time_from_proto(Some(f64::NAN)).is_err());
        assert_eq!(time_from_proto(Some(0.5)).ok().flatten(), Some(0.5));
    }
}
