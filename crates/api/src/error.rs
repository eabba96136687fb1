//! The one error shape of the REST API: `{"error": {"code": "...", "message": "..."}}`.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use segsplat_scene::InputErrorClass;
use segsplat_service::store::{BlobError, StoreError};
use segsplat_service::usecases::jobs::JobFailure;
use segsplat_service::usecases::scenes::SceneFailure;

#[derive(Debug, Clone)]
pub struct ApiError {
    pub status: StatusCode,
    /// Stable machine-readable code, e.g. `not_found`, `payload_too_large`.
    pub code: &'static str,
    pub message: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ErrorBody {
    pub error: ErrorDetail,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ErrorDetail {
    pub code: String,
    pub message: String,
}

impl ApiError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        Self {
            status,
            code,
            message: message.into(),
        }
    }

    pub fn not_found(message: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, "not_found", message)
    }

    pub fn bad_request(message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, "bad_request", message)
    }

    pub fn forbidden(message: impl Into<String>) -> Self {
        Self::new(StatusCode::FORBIDDEN, "forbidden", message)
    }

    pub fn conflict(message: impl Into<String>) -> Self {
        Self::new(StatusCode::CONFLICT, "conflict", message)
    }

    pub fn unprocessable(message: impl Into<String>) -> Self {
        Self::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_input", message)
    }

    pub fn payload_too_large(message: impl Into<String>) -> Self {
        Self::new(StatusCode::PAYLOAD_TOO_LARGE, "payload_too_large", message)
    }

    pub fn unsupported_media_type(message: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            message,
        )
    }

    pub fn unauthorized() -> Self {
        Self::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "missing or invalid bearer token",
        )
    }

    /// A store the service depends on (database, object store) is down; retry later.
    pub fn unavailable(message: impl Into<String>) -> Self {
        Self::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message)
    }

    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", message)
    }

    /// A request the framework refused before a handler ran (axum's rejection status and text),
    /// with the code the same status has elsewhere in the API.
    pub fn rejected(status: StatusCode, message: impl Into<String>) -> Self {
        let code = match status {
            StatusCode::BAD_REQUEST => "bad_request",
            StatusCode::PAYLOAD_TOO_LARGE => "payload_too_large",
            StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
            StatusCode::UNPROCESSABLE_ENTITY => "invalid_input",
            status if status.is_server_error() => "internal",
            _ => "bad_request",
        };
        Self::new(status, code, message)
    }

    /// Maps a rejected input's class to its status (400/413/415/422/500).
    pub fn from_input_class(class: InputErrorClass, message: impl Into<String>) -> Self {
        match class {
            InputErrorClass::Malformed => {
                Self::new(StatusCode::BAD_REQUEST, "malformed_input", message)
            }
            InputErrorClass::TooLarge => Self::payload_too_large(message),
            InputErrorClass::UnsupportedFormat => Self::unsupported_media_type(message),
            InputErrorClass::Invalid => Self::unprocessable(message),
            InputErrorClass::Internal => Self::internal(message),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        if self.status.is_server_error() {
            tracing::error!(code = self.code, message = %self.message, "request failed");
        }
        let body = ErrorBody {
            error: ErrorDetail {
                code: self.code.to_string(),
                message: self.message,
            },
        };
        (self.status, Json(body)).into_response()
    }
}

impl From<StoreError> for ApiError {
    fn from(error: StoreError) -> Self {
        if error.is_unavailable() {
            ApiError::unavailable(error.to_string())
        } else {
            ApiError::internal(error.to_string())
        }
    }
}

impl From<BlobError> for ApiError {
    fn from(error: BlobError) -> Self {
        match error {
            BlobError::Unavailable { .. } => ApiError::unavailable(error.to_string()),
            other => ApiError::internal(other.to_string()),
        }
    }
}

impl From<SceneFailure> for ApiError {
    fn from(failure: SceneFailure) -> Self {
        let message = failure.to_string();
        match failure {
            SceneFailure::NotFound(_) => ApiError::not_found(message),
            SceneFailure::Rejected { class, .. } => ApiError::from_input_class(class, message),
            SceneFailure::Busy { .. } => ApiError::conflict(message),
            SceneFailure::Blob(blob) => blob.into(),
            SceneFailure::Store(store) => store.into(),
            SceneFailure::Internal(_) => ApiError::internal(message),
        }
    }
}

impl From<JobFailure> for ApiError {
    fn from(failure: JobFailure) -> Self {
        let message = failure.to_string();
        match failure {
            JobFailure::NotFound(_) | JobFailure::SceneNotFound(_) => ApiError::not_found(message),
            JobFailure::Invalid(_) => ApiError::unprocessable(message),
            JobFailure::UnknownState(_) => ApiError::bad_request(message),
            JobFailure::AlreadyFinished { .. } => ApiError::conflict(message),
            JobFailure::Store(store) => store.into(),
        }
    }
}

pub type ApiResult<T> = Result<T, ApiError>;
