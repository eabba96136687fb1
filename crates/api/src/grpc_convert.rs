//! gRPC messages to and from the service's typed core: requests' enums, views and times into the
//! use cases' types, records into messages, and each use case's failure into a status code.

use tonic::Status;

use crate::proto;
use segsplat_scene::Level;
use segsplat_service::serving::SceneCamera;
use segsplat_service::serving::{
    EncodedMask, EncodedMaskData, MaskFormat, MaskView, PinholeIntrinsics, ServingError,
};
use segsplat_service::store::jobs::{JobRecord, JobState};
use segsplat_service::store::objects::ObjectRecord;
use segsplat_service::store::scenes::SceneRecord;
use segsplat_service::store::{BlobError, StoreError};
use segsplat_service::usecases::jobs::JobFailure;
use segsplat_service::usecases::query::QueryFailure;
use segsplat_service::usecases::scenes::SceneFailure;
use segsplat_service::usecases::serving::ServeFailure;
use segsplat_vision::language::Granularity;

pub(crate) fn mask_format_from_proto(value: i32) -> Result<Option<MaskFormat>, Status> {
    match proto::MaskEncoding::try_from(value) {
        Ok(proto::MaskEncoding::None) => Ok(None),
        Ok(proto::MaskEncoding::Png) => Ok(Some(MaskFormat::Png)),
        Ok(proto::MaskEncoding::CocoRle) => Ok(Some(MaskFormat::CocoRle)),
        Err(_) => Err(Status::invalid_argument(format!(
            "mask_encoding: unknown value {value}"
        ))),
    }
}

/// A requested time, checked to be a number.
pub(crate) fn time_from_proto(time: Option<f64>) -> Result<Option<f32>, Status> {
    match time {
        Some(value) if !value.is_finite() => Err(Status::invalid_argument(format!(
            "time: {value} is not a finite number"
        ))),
        other => Ok(other.map(|value| value as f32)),
    }
}

pub(crate) fn view_from_proto(view: &proto::View) -> Result<MaskView, Status> {
    match &view.source {
        Some(proto::view::Source::FrameIndex(index)) => Ok(MaskView::Frame {
            index: *index as usize,
            max_side: view.max_side,
        }),
        Some(proto::view::Source::Pose(pose)) => pose_view_from_proto(pose),
        None => Err(Status::invalid_argument("view: set frame_index or pose")),
    }
}

fn pose_view_from_proto(view: &proto::PoseView) -> Result<MaskView, Status> {
    let values = view
        .pose
        .as_ref()
        .map(|pose| pose.camera_to_world.as_slice())
        .unwrap_or_default();
    if values.len() != 16 {
        return Err(Status::invalid_argument(format!(
            "view.pose.camera_to_world: expected 16 values (row-major 4x4), got {}",
            values.len()
        )));
    }
    let mut rows = [[0.0f64; 4]; 4];
    for (index, value) in values.iter().enumerate() {
        rows[index / 4][index % 4] = *value;
    }
    let intrinsics = view
        .intrinsics
        .as_ref()
        .ok_or_else(|| Status::invalid_argument("view.intrinsics: required with a pose"))?;
    Ok(MaskView::Pose {
        camera_to_world: rows,
        intrinsics: PinholeIntrinsics {
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            width: intrinsics.width,
            height: intrinsics.height,
        },
    })
}

pub(crate) fn mask_to_proto(mask: &EncodedMask, amodal: bool) -> proto::Mask {
    let (encoding, data) = match &mask.data {
        EncodedMaskData::Png(bytes) => (proto::MaskEncoding::Png, bytes.clone()),
        EncodedMaskData::CocoRle(counts) => {
            (proto::MaskEncoding::CocoRle, counts.as_bytes().to_vec())
        }
    };
    proto::Mask {
        encoding: encoding as i32,
        width: mask.width,
        height: mask.height,
        data,
        amodal,
    }
}

pub(crate) fn serve_failure_status(failure: ServeFailure) -> Status {
    let message = failure.to_string();
    match failure {
        ServeFailure::SceneNotFound(_)
        | ServeFailure::FileNotStored { .. }
        | ServeFailure::UnknownFile(_) => Status::not_found(message),
        ServeFailure::NotTrained(_) => Status::failed_precondition(message),
        ServeFailure::StaticScene(_) => Status::invalid_argument(message),
        ServeFailure::Blobs(_) => Status::unavailable(message),
        ServeFailure::DeadlineExceeded => Status::deadline_exceeded(message),
        ServeFailure::CallerGone => Status::cancelled(message),
        ServeFailure::Serving(error) => match error {
            ServingError::FrameOutOfRange { .. } | ServingError::BadView(_) => {
                Status::invalid_argument(message)
            }
            ServingError::NoSuchObject { .. } => Status::not_found(message),
            ServingError::MissingFile { .. } => Status::failed_precondition(message),
            ServingError::NoGpu(_) => Status::unavailable(message),
            ServingError::Corrupt { .. }
            | ServingError::Storage(_)
            | ServingError::Gpu(_)
            | ServingError::Encoding(_) => {
                tracing::error!(%message, "gRPC mask request failed");
                Status::internal(message)
            }
        },
        ServeFailure::Store(store) => internal(store),
        ServeFailure::Worker(_) => {
            tracing::error!(%message, "gRPC mask request failed");
            Status::internal(message)
        }
    }
}

pub(crate) fn query_failure_status(failure: QueryFailure) -> Status {
    let message = failure.to_string();
    match failure {
        QueryFailure::BadOptions(_) | QueryFailure::EmptyText => Status::invalid_argument(message),
        QueryFailure::SceneNotFound(_) => Status::not_found(message),
        QueryFailure::NoObjects(_) | QueryFailure::NoEmbeddings { .. } => {
            Status::failed_precondition(message)
        }
        QueryFailure::NoTextEncoder(_) | QueryFailure::EmbeddingWidth(_) => {
            Status::unavailable(message)
        }
        QueryFailure::Store(store) => internal(store),
        QueryFailure::Encoding(_) => {
            tracing::error!(%message, "gRPC query failed");
            Status::internal(message)
        }
    }
}

pub(crate) fn granularity_from_proto(value: i32) -> Result<Granularity, Status> {
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

pub(crate) fn scene_failure_status(failure: SceneFailure) -> Status {
    let message = failure.to_string();
    match failure {
        SceneFailure::NotFound(_) => Status::not_found(message),
        SceneFailure::Rejected { .. } => Status::invalid_argument(message),
        SceneFailure::Busy { .. } => Status::failed_precondition(message),
        SceneFailure::Blob(BlobError::Unavailable { .. }) => Status::unavailable(message),
        SceneFailure::Store(store) => internal(store),
        SceneFailure::Blob(_) | SceneFailure::Internal(_) => {
            tracing::error!(%message, "gRPC scene request failed");
            Status::internal(message)
        }
    }
}

pub(crate) fn job_failure_status(failure: JobFailure) -> Status {
    let message = failure.to_string();
    match failure {
        JobFailure::NotFound(_) | JobFailure::SceneNotFound(_) => Status::not_found(message),
        JobFailure::Invalid(_) | JobFailure::UnknownState(_) => Status::invalid_argument(message),
        JobFailure::AlreadyFinished { .. } => Status::failed_precondition(message),
        JobFailure::Store(store) => internal(store),
    }
}

/// A store failure: UNAVAILABLE while the database cannot be reached (the client may retry),
/// INTERNAL otherwise.
pub(crate) fn internal(error: StoreError) -> Status {
    if error.is_unavailable() {
        tracing::warn!(%error, "gRPC request: database unavailable");
        return Status::unavailable(error.to_string());
    }
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

pub(crate) fn level_from_proto(level: proto::Level) -> Option<Level> {
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
    let parsed: segsplat_service::jobs::Progress = serde_json::from_value(progress.clone()).ok()?;
    Some(proto::Progress {
        stage: parsed.stage,
        step: parsed.step,
        total_steps: parsed.total_steps,
        metrics: parsed.metrics.into_iter().collect(),
        eta_secs: parsed.eta_secs,
    })
}

pub(crate) fn job_to_proto(job: JobRecord) -> proto::Job {
    proto::Job {
        state: job_state_to_proto(job.state) as i32,
        progress: job.progress.as_ref().and_then(progress_to_proto),
        config_json: job.config.to_string(),
        settings_json: job.settings.as_ref().map(serde_json::Value::to_string),
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

pub(crate) fn scene_to_proto(scene: SceneRecord) -> proto::Scene {
    proto::Scene {
        format: serde_json::to_value(scene.summary.format)
            .ok()
            .and_then(|value| value.as_str().map(str::to_string))
            .unwrap_or_default(),
        frame_count: scene.summary.frame_count,
        sparse_point_count: scene.summary.sparse_point_count,
        has_masks: !scene.summary.mask_levels.is_empty(),
        dynamic: scene.summary.time_count > 0,
        time_count: scene.summary.time_count,
        resolutions: scene
            .summary
            .resolutions
            .iter()
            .map(|&[width, height]| proto::FrameSize { width, height })
            .collect(),
        id: scene.id,
        name: scene.name,
        created_at_ms: scene.created_at_ms,
    }
}

pub(crate) fn camera_to_proto(frame_index: usize, camera: SceneCamera) -> proto::Camera {
    proto::Camera {
        frame_index: u32::try_from(frame_index).unwrap_or(u32::MAX),
        pose: Some(proto::Pose {
            camera_to_world: camera
                .camera_to_world
                .iter()
                .flatten()
                .map(|&value| f64::from(value))
                .collect(),
        }),
        intrinsics: Some(proto::Intrinsics {
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
            width: camera.width,
            height: camera.height,
        }),
        time: camera.time.map(f64::from),
        name: camera.name,
    }
}

pub(crate) fn object_to_proto(object: ObjectRecord) -> proto::ObjectInfo {
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
