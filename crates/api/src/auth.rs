//! Optional bearer-token authentication for REST (middleware) and gRPC (interceptor). Health,
//! readiness and metrics stay open so probes and scrapers need no secret, and so does the
//! OpenAPI document, which holds no tenant's data and tells a client how to authenticate, and the
//! web console's static files (they call the API with the token the user enters).
//!
//! A token resolves to the [`Caller`] it acts for (tenant, admin), which the middleware and the
//! interceptor attach to the request; handlers hand it to the store, which filters by it.

use std::sync::Arc;

use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use segsplat_service::config::AuthConfig;
use segsplat_service::store::{Caller, DEFAULT_TENANT};

/// Paths reachable without a token (the OpenAPI document declares them with `security: []`).
pub const OPEN_PATHS: [&str; 4] = ["/healthz", "/readyz", "/metrics", "/v1/openapi.json"];

#[derive(Debug, Clone, Default)]
pub struct TokenCheck {
    tokens: Arc<Vec<(String, Caller)>>,
}

impl TokenCheck {
    /// Every configured token with the caller it acts for: plain tokens for the default tenant.
    pub fn from_config(auth: &AuthConfig) -> Self {
        let plain = auth
            .tokens
            .iter()
            .map(|token| (token.trim().to_string(), Caller::tenant(DEFAULT_TENANT)));
        let tenant = auth.token.iter().map(|entry| {
            let caller = Caller {
                tenant: entry.tenant_name().to_string(),
                admin: entry.admin,
            };
            (entry.token.trim().to_string(), caller)
        });
        Self {
            tokens: Arc::new(plain.chain(tenant).collect()),
        }
    }

    pub fn enabled(&self) -> bool {
        !self.tokens.is_empty()
    }

    /// Who an `Authorization` header value acts for; `None` when it carries no accepted token.
    /// With authentication off every caller is [`Caller::system`] (sees everything).
    pub fn caller(&self, header_value: Option<&str>) -> Option<Caller> {
        if !self.enabled() {
            return Some(Caller::system());
        }
        let token = header_value.and_then(|value| {
            value
                .strip_prefix("Bearer ")
                .or_else(|| value.strip_prefix("bearer "))
        })?;
        // Every configured token is compared, so timing does not tell which one nearly matched.
        self.tokens
            .iter()
            .fold(None, |found, (accepted, caller)| {
                let matches = constant_time_eq(accepted, token.trim());
                found.or(matches.then_some(caller))
            })
            .cloned()
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

/// Admits requests with an accepted token (or to an open path) and attaches their [`Caller`]
/// for the handlers' `Extension<Caller>`.
pub async fn require_token(
    State(check): State<TokenCheck>,
    mut request: Request,
    next: Next,
) -> Response {
    let path = request.uri().path();
    if OPEN_PATHS.contains(&path) || super::console::is_console_path(path) {
        return next.run(request).await;
    }
    let header = request
        .headers()
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|value| value.to_str().ok());
    match check.caller(header) {
        Some(caller) => {
            request.extensions_mut().insert(caller);
            next.run(request).await
        }
        None => ApiError::unauthorized().into_response(),
    }
}

/// The caller the interceptor attached to a gRPC request.
pub fn grpc_caller<T>(request: &tonic::Request<T>) -> Result<Caller, tonic::Status> {
    request
        .extensions()
        .get::<Caller>()
        .cloned()
        .ok_or_else(|| tonic::Status::unauthenticated("the request carries no resolved caller"))
}

/// gRPC interceptor with the same tokens (metadata `authorization: Bearer ...`).
pub fn grpc_interceptor(
    check: TokenCheck,
) -> impl FnMut(tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> + Clone {
    move |mut request: tonic::Request<()>| {
        let header = request
            .metadata()
            .get("authorization")
            .and_then(|value| value.to_str().ok());
        match check.caller(header) {
            Some(caller) => {
                request.extensions_mut().insert(caller);
                Ok(request)
            }
            None => Err(tonic::Status::unauthenticated(
                "missing or invalid bearer token in the authorization metadata",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use segsplat_service::config::TenantToken;

    #[test]
    fn tokens_resolve_to_their_tenant() {
        let open = TokenCheck::from_config(&AuthConfig::default());
        assert_eq!(open.caller(None), Some(Caller::system()));
        let check = TokenCheck::from_config(&AuthConfig {
            tokens: vec!["s3cret".to_string(), "other".to_string()],
            token: vec![
                TenantToken {
                    token: "alpha-key".to_string(),
                    tenant: Some("alpha".to_string()),
                    admin: false,
                },
                TenantToken {
                    token: "root-key".to_string(),
                    tenant: None,
                    admin: true,
                },
            ],
        });
        let plain = Some(Caller::tenant(DEFAULT_TENANT));
        assert_eq!(check.caller(Some("Bearer s3cret")), plain);
        assert_eq!(check.caller(Some("Bearer other")), plain);
        assert_eq!(
            check.caller(Some("Bearer alpha-key")),
            Some(Caller::tenant("alpha"))
        );
        assert_eq!(
            check.caller(Some("Bearer root-key")),
            Some(Caller::admin(DEFAULT_TENANT))
        );
        assert_eq!(check.caller(Some("Bearer s3cre")), None);
        assert_eq!(check.caller(Some("s3cret")), None);
        assert_eq!(check.caller(None), None);
    }
}
