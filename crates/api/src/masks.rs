//! Mask endpoints: `POST /v1/scenes/{id}/masks` (any objects, any view, PNG or COCO RLE in
//! JSON) and `GET /v1/scenes/{id}/objects/{level}/{object_id}/mask.png` (one object, one frame,
//! a plain PNG for browsers and curl). Also the view and mask JSON shapes the query endpoint
//! shares.

use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use base64::Engine;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::error::{ApiError, ApiResult, ErrorBody};
use super::extract::{JsonBody, Query, UrlPath};
use super::params::{parse_level, parse_mask_format, parse_time};
use super::schema_names::{BinaryFile, LevelName, MaskFormatName, TimeValue};
use super::state::AppState;
use segsplat_service::serving::{
    EncodedMask, EncodedMaskData, MaskFormat, MaskView, PinholeIntrinsics, ServingError,
};
use segsplat_service::store::Caller;
use segsplat_service::usecases::serving::{EncodedObjectMasks, ServeFailure};

/// Most objects one mask request may ask for.
const MAX_OBJECTS_PER_REQUEST: usize = 64;

impl From<ServeFailure> for ApiError {
    fn from(failure: ServeFailure) -> Self {
        let message = failure.to_string();
        match failure {
            ServeFailure::SceneNotFound(_) | ServeFailure::FileNotStored { .. } => {
                ApiError::not_found(message)
            }
            ServeFailure::NotTrained(_) => ApiError::conflict(message),
            ServeFailure::UnknownFile(_) => ApiError::not_found(message),
            ServeFailure::StaticScene(_) => ApiError::bad_request(message),
            ServeFailure::Blobs(blob) => blob.into(),
            ServeFailure::DeadlineExceeded => {
                ApiError::new(StatusCode::GATEWAY_TIMEOUT, "deadline_exceeded", message)
            }
            // Nobody reads it: the client disconnected. nginx's "client closed request".
            ServeFailure::CallerGone => ApiError::new(
                StatusCode::from_u16(499).unwrap_or(StatusCode::REQUEST_TIMEOUT),
                "caller_gone",
                message,
            ),
            ServeFailure::Serving(error) => match error {
                ServingError::FrameOutOfRange { .. } | ServingError::BadView(_) => {
                    ApiError::bad_request(message)
                }
                ServingError::NoSuchObject { .. } => ApiError::not_found(message),
                ServingError::MissingFile { .. } => ApiError::conflict(message),
                ServingError::NoGpu(_) => {
                    ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message)
                }
                ServingError::Corrupt { .. }
                | ServingError::Storage(_)
                | ServingError::Gpu(_)
                | ServingError::Encoding(_) => ApiError::internal(message),
            },
            ServeFailure::Store(store) => store.into(),
            ServeFailure::Worker(_) => ApiError::internal(message),
        }
    }
}

/// The view to render masks for: either `frame_index` (with optional `max_side`), or
/// `camera_to_world` with `intrinsics`. Its schema (`view_schema.rs`) states the two shapes.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewRequest {
    /// One of the scene's frames, 0-based in dataset order (`cameras.json`).
    pub frame_index: Option<u32>,
    /// With `frame_index`: the longest side of the mask in pixels (default: the frame's size;
    /// larger values are capped at the frame's size and `query.max_mask_side`).
    pub max_side: Option<u32>,
    /// Camera-to-world, row-major 4x4 (last row 0 0 0 1), OpenCV axes (x right, y down,
    /// z forward), in the scene's world frame and units.
    pub camera_to_world: Option<[[f64; 4]; 4]>,
    pub intrinsics: Option<PinholeIntrinsics>,
    /// Dynamic scenes: the normalised capture time (0..1 spans the training frames) to render
    /// at. Default: the frame's own time for `frame_index`, else the scene's first time. Static
    /// scenes ignore it.
    pub time: Option<f64>,
}

impl ViewRequest {
    pub fn time(&self) -> Result<Option<f32>, ApiError> {
        parse_time(self.time)
    }

    pub fn to_view(&self) -> Result<MaskView, ApiError> {
        match (self.frame_index, self.camera_to_world, self.intrinsics) {
            (Some(index), None, None) => Ok(MaskView::Frame {
                index: index as usize,
                max_side: self.max_side,
            }),
            (None, Some(camera_to_world), Some(intrinsics)) if self.max_side.is_none() => {
                Ok(MaskView::Pose {
                    camera_to_world,
                    intrinsics,
                })
            }
            _ => Err(ApiError::bad_request(
                "view: give either frame_index (and optionally max_side), or camera_to_world \
                 and intrinsics",
            )),
        }
    }
}

/// A rendered mask.
#[derive(Debug, Serialize, ToSchema)]
pub struct MaskBody {
    /// `png` or `coco_rle`.
    #[schema(value_type = MaskFormatName)]
    pub format: String,
    pub width: u32,
    pub height: u32,
    /// `png`: the PNG file, base64 (8-bit grey, 255 inside). `coco_rle`: the compressed counts
    /// string; pycocotools decodes `{"size": [height, width], "counts": data}`.
    pub data: String,
}

impl From<&EncodedMask> for MaskBody {
    fn from(mask: &EncodedMask) -> Self {
        let (format, data) = match &mask.data {
            EncodedMaskData::Png(bytes) => (
                "png",
                base64::engine::general_purpose::STANDARD.encode(bytes),
            ),
            EncodedMaskData::CocoRle(counts) => ("coco_rle", counts.clone()),
        };
        Self {
            format: format.to_string(),
            width: mask.width,
            height: mask.height,
            data,
        }
    }
}

/// An object of one level.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ObjectRef {
    /// `small`, `middle` or `large`.
    #[schema(value_type = LevelName)]
    pub level: String,
    #[schema(maximum = 4294967295_u64)]
    pub object_id: u32,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MasksRequest {
    /// 1..=64 objects.
    #[schema(min_items = 1, max_items = 64)]
    pub objects: Vec<ObjectRef>,
    pub view: ViewRequest,
    /// `coco_rle` (default) or `png`.
    #[schema(value_type = Option<MaskFormatName>)]
    pub mask_format: Option<String>,
    /// Also return each object's visible-only mask (the part no other Gaussian hides).
    pub visible_masks: Option<bool>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ObjectMasksResponse {
    #[schema(value_type = LevelName)]
    pub level: String,
    pub object_id: u32,
    /// Alpha > 0.5 of the object rendered alone: occluded parts included.
    pub mask: MaskBody,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub visible_mask: Option<MaskBody>,
}

impl From<&EncodedObjectMasks> for ObjectMasksResponse {
    fn from(masks: &EncodedObjectMasks) -> Self {
        Self {
            level: masks.level.name().to_string(),
            object_id: masks.object_id,
            mask: MaskBody::from(&masks.mask),
            visible_mask: masks.visible_mask.as_ref().map(MaskBody::from),
        }
    }
}

#[derive(Debug, Serialize, ToSchema)]
pub struct MasksResponse {
    pub masks: Vec<ObjectMasksResponse>,
}

#[utoipa::path(post, path = "/v1/scenes/{id}/masks", tag = "objects",
    params(("id" = String, Path, description = "scene id")),
    request_body = MasksRequest,
    responses((status = 200, description = "one mask (and visible mask) per object, in \
               the order asked", body = MasksResponse),
              (status = 400, description = "bad view, level, format or object count",
               body = ErrorBody),
              (status = 404, description = "unknown scene or object", body = ErrorBody),
              (status = 409, description = "the scene is not trained yet", body = ErrorBody),
              (status = 503, description = "no GPU to render on", body = ErrorBody),
              (status = 504, description = "rendering took too long", body = ErrorBody)))]
pub async fn render_masks(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath(id): UrlPath<String>,
    JsonBody(request): JsonBody<MasksRequest>,
) -> ApiResult<Json<MasksResponse>> {
    if request.objects.is_empty() || request.objects.len() > MAX_OBJECTS_PER_REQUEST {
        return Err(ApiError::bad_request(format!(
            "objects: give 1 to {MAX_OBJECTS_PER_REQUEST} objects"
        )));
    }
    let objects = request
        .objects
        .iter()
        .map(|object| Ok((parse_level(&object.level)?, object.object_id)))
        .collect::<Result<Vec<_>, ApiError>>()?;
    let view = request.view.to_view()?;
    let time = request.view.time()?;
    let format = parse_mask_format(request.mask_format.as_deref())?;
    let masks = state
        .core
        .serving
        .render_masks(
            &id,
            &caller,
            view,
            time,
            objects,
            request.visible_masks.unwrap_or(false),
            format,
        )
        .await?;
    Ok(Json(MasksResponse {
        masks: masks.iter().map(ObjectMasksResponse::from).collect(),
    }))
}

#[derive(Debug, Deserialize, IntoParams)]
pub struct MaskPngParams {
    /// Frame index, 0-based in dataset order (`cameras.json`); one the scene does not have
    /// is 400 (the scene's frame count is not in the schema).
    #[param(maximum = 4294967295_u64)]
    pub frame_index: u32,
    /// Longest side in pixels (default: the frame's size).
    #[param(minimum = 1, maximum = 4294967295_u64)]
    pub max_side: Option<u32>,
    /// `true`: only the part no other Gaussian hides.
    pub visible: Option<bool>,
    /// Dynamic scenes: the time to render at (default: the frame's own time).
    #[param(value_type = Option<TimeValue>)]
    pub time: Option<f64>,
}

#[utoipa::path(get, path = "/v1/scenes/{id}/objects/{level}/{object_id}/mask.png",
    tag = "objects",
    params(("id" = String, Path, description = "scene id"),
           ("level" = LevelName, Path, description = "small, middle or large"),
           ("object_id" = u32, Path, description = "object id at that level",
            maximum = 4294967295_u64),
           MaskPngParams),
    responses((status = 200, description = "8-bit grey PNG, 255 inside", content_type = "image/png",
               body = BinaryFile),
              (status = 400, description = "unknown level, bad frame index or size", body = ErrorBody),
              (status = 404, description = "unknown scene or object", body = ErrorBody),
              (status = 409, description = "the scene is not trained yet", body = ErrorBody),
              (status = 503, description = "no GPU to render on", body = ErrorBody),
              (status = 504, description = "rendering took too long", body = ErrorBody)))]
pub async fn object_mask_png(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    UrlPath((id, level, object_id)): UrlPath<(String, String, u32)>,
    Query(params): Query<MaskPngParams>,
) -> ApiResult<Response> {
    let level = parse_level(&level)?;
    let visible = params.visible.unwrap_or(false);
    let view = MaskView::Frame {
        index: params.frame_index as usize,
        max_side: params.max_side,
    };
    let masks = state
        .core
        .serving
        .render_masks(
            &id,
            &caller,
            view,
            parse_time(params.time)?,
            vec![(level, object_id)],
            visible,
            MaskFormat::Png,
        )
        .await?;
    let Some(first) = masks.first() else {
        return Err(ApiError::internal("no mask rendered"));
    };
    let chosen = if visible {
        first.visible_mask.as_ref().unwrap_or(&first.mask)
    } else {
        &first.mask
    };
    let EncodedMaskData::Png(bytes) = &chosen.data else {
        return Err(ApiError::internal("mask was not encoded as PNG"));
    };
    Ok(([(header::CONTENT_TYPE, "image/png")], bytes.clone()).into_response())
}
