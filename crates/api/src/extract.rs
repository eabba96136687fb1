//! The REST extractors: axum's `Json`, `Query` and `Path` whose rejections (a malformed JSON
//! body, a missing JSON content type, a body over the limit, a bad query string or path segment)
//! answer in the API's JSON error envelope instead of axum's `text/plain`. Handlers use these,
//! so the mapping lives here once; the router's fallbacks cover unknown routes and methods.

use axum::extract::rejection::{JsonRejection, PathRejection, QueryRejection};
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::StatusCode;

use serde::de::DeserializeOwned;
use serde_json::Value;

use super::error::ApiError;
use super::json_numbers::whole_numbers;

/// `axum::Json`, rejecting with the error envelope, and reading integral floats as integers
/// ([`whole_numbers`]).
#[derive(Debug)]
pub struct JsonBody<T>(pub T);

impl<T, S> FromRequest<S> for JsonBody<T>
where
    T: DeserializeOwned,
    S: Send + Sync,
{
    type Rejection = ApiError;

    async fn from_request(request: Request, state: &S) -> Result<Self, ApiError> {
        // Content type, size limit and syntax are axum's checks (and its messages).
        let axum::Json(value) = axum::Json::<Value>::from_request(request, state).await?;
        // Read again into `T` from the normalised text, so data errors keep axum's messages,
        // which name the field's path.
        let text = serde_json::to_vec(&whole_numbers(value))
            .map_err(|error| ApiError::internal(format!("cannot re-encode the body: {error}")))?;
        let axum::Json(body) = axum::Json::<T>::from_bytes(&text)?;
        Ok(JsonBody(body))
    }
}

/// `axum::extract::Query`, rejecting with the error envelope.
#[derive(Debug, FromRequestParts)]
#[from_request(via(axum::extract::Query), rejection(ApiError))]
pub struct Query<T>(pub T);

/// `axum::extract::Path`, rejecting with the error envelope.
#[derive(Debug, FromRequestParts)]
#[from_request(via(axum::extract::Path), rejection(ApiError))]
pub struct UrlPath<T>(pub T);

impl From<JsonRejection> for ApiError {
    fn from(rejection: JsonRejection) -> Self {
        ApiError::rejected(rejection.status(), rejection.body_text())
    }
}

impl From<QueryRejection> for ApiError {
    fn from(rejection: QueryRejection) -> Self {
        ApiError::rejected(rejection.status(), rejection.body_text())
    }
}

impl From<PathRejection> for ApiError {
    fn from(rejection: PathRejection) -> Self {
        ApiError::rejected(rejection.status(), rejection.body_text())
    }
}

/// Answers a known path asked with a method it does not have (axum adds the `Allow` header).
pub async fn method_not_allowed() -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        "this path does not accept that method (the Allow header lists the ones it does)",
    )
}

/// Answers a path no route matches.
pub async fn no_such_endpoint() -> ApiError {
    ApiError::not_found("no such endpoint")
}
