//! Optional bearer-token authentication for REST (middleware) and gRPC (interceptor). Health,
//! readiness and metrics stay open so probes and scrapers need no secret.

use std::sync::Arc;

use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;

/// Paths reachable without a token.
const OPEN_PATHS: [&str; 3] = ["/healthz", "/readyz", "/metrics"];

#[derive(Debug, Clone, Default)]
pub struct TokenCheck {
    tokens: Arc<Vec<String>>,
}

impl TokenCheck {
    pub fn new(tokens: Vec<String>) -> Self {
        Self {
            tokens: Arc::new(tokens),
        }
    }

    pub fn enabled(&self) -> bool {
        !self.tokens.is_empty()
    }

    /// Whether an `Authorization` header value carries an accepted token.
    pub fn accepts(&self, header_value: Option<&str>) -> bool {
        if !self.enabled() {
            return true;
        }
        let Some(token) = header_value.and_then(|value| {
            value
                .strip_prefix("Bearer ")
                .or_else(|| value.strip_prefix("bearer "))
        }) else {
            return false;
        };
        self.tokens.iter().fold(false, |found, accepted| {
            found | constant_time_eq(accepted, token.trim())
        })
    }
}

/// Compares without exiting at the first differing byte, so response times do not leak how
/// much of a guessed token was right.
fn constant_time_eq(left: &str, right: &str) -> bool {
    if left.len() != right.len() {
        return false;
    }
    left.bytes()
        .zip(right.bytes())
        .fold(0u8, |difference, (a, b)| difference | (a ^ b))
        == 0
}

pub async fn require_token(
    State(check): State<TokenCheck>,
    request: Request,
    next: Next,
) -> Response {
    if OPEN_PATHS.contains(&request.uri().path()) {
        return next.run(request).await;
    }
    let header = request
        .headers()
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|value| value.to_str().ok());
    if check.accepts(header) {
        next.run(request).await
    } else {
        ApiError::unauthorized().into_response()
    }
}

/// gRPC interceptor with the same tokens (metadata `authorization: Bearer ...`).
pub fn grpc_interceptor(
    check: TokenCheck,
) -> impl FnMut(tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> + Clone {
    move |request: tonic::Request<()>| {
        let header = request
            .metadata()
            .get("authorization")
            .and_then(|value| value.to_str().ok());
        if check.accepts(header) {
            Ok(request)
        } else {
            Err(tonic::Status::unauthenticated(
                "missing or invalid bearer token in the authorization metadata",
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_only_configured_tokens() {
        let open = TokenCheck::new(vec![]);
        assert!(open.accepts(None));
        let check = TokenCheck::new(vec!["s3cret".to_string(), "other".to_string()]);
        assert!(check.accepts(Some("Bearer s3cret")));
        assert!(check.accepts(Some("Bearer other")));
        assert!(!check.accepts(Some("Bearer s3cre")));
        assert!(!check.accepts(Some("s3cret")));
        assert!(!check.accepts(None));
    }
}
