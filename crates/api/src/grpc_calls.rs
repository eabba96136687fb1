//! What every gRPC call goes through, as one tower layer around the tonic server (SceneQuery,
//! health and reflection alike):
//!
//! - **Metrics**: request counts and latency by method. The latency is the time to the
//!   response's headers (for a stream, to its first message).
//! - **Deadlines** (`grpc-timeout`): a call whose deadline passes is answered
//!   `DEADLINE_EXCEEDED`. tonic enforces the header itself but answers `CANCELLED` ("Timeout
//!   expired"), which clients cannot tell from a cancel; this layer, inside tonic's, sets its
//!   own timer a little earlier and answers first. It also hands the deadline to the use cases
//!   (`usecases::observe::with_deadline`), so a mask render still queued for the GPU at the
//!   deadline is not started.
//! - The use cases' own histograms are labelled `api="grpc"` (`usecases::observe`).

use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use futures::future::BoxFuture;
use segsplat_service::usecases::observe::{called_from, with_deadline};

/// Methods outside these services are counted as `unknown`, so a client cannot grow the label
/// set with made-up paths.
const KNOWN_SERVICES: [&str; 4] = [
    "/segsplat.v1.",
    "/grpc.health.v1.",
    "/grpc.reflection.v1.",
    "/grpc.reflection.v1alpha.",
];

/// How much earlier than tonic's own timer this layer's fires: a tenth of the budget, between
/// 1 and 20 ms, so a loaded runtime still wakes this timer first.
fn ahead_of_tonic(timeout: Duration) -> Duration {
    (timeout / 10).clamp(Duration::from_millis(1), Duration::from_millis(20))
}

/// The canonical name of a `grpc-status` value (`NOT_FOUND` for `5`), as gRPC's own docs and
/// other servers' metrics spell it; none is `OK`, an unknown value `UNKNOWN` (so a peer cannot
/// grow the label set).
pub fn code_name(status: Option<&str>) -> &'static str {
    let Some(status) = status else {
        return "OK";
    };
    match status.parse::<i32>().map(tonic::Code::from) {
        Ok(tonic::Code::Ok) => "OK",
        Ok(tonic::Code::Cancelled) => "CANCELLED",
        Ok(tonic::Code::InvalidArgument) => "INVALID_ARGUMENT",
        Ok(tonic::Code::DeadlineExceeded) => "DEADLINE_EXCEEDED",
        Ok(tonic::Code::NotFound) => "NOT_FOUND",
        Ok(tonic::Code::AlreadyExists) => "ALREADY_EXISTS",
        Ok(tonic::Code::PermissionDenied) => "PERMISSION_DENIED",
        Ok(tonic::Code::ResourceExhausted) => "RESOURCE_EXHAUSTED",
        Ok(tonic::Code::FailedPrecondition) => "FAILED_PRECONDITION",
        Ok(tonic::Code::Aborted) => "ABORTED",
        Ok(tonic::Code::OutOfRange) => "OUT_OF_RANGE",
        Ok(tonic::Code::Unimplemented) => "UNIMPLEMENTED",
        Ok(tonic::Code::Internal) => "INTERNAL",
        Ok(tonic::Code::Unavailable) => "UNAVAILABLE",
        Ok(tonic::Code::DataLoss) => "DATA_LOSS",
        Ok(tonic::Code::Unauthenticated) => "UNAUTHENTICATED",
        Ok(tonic::Code::Unknown) | Err(_) => "UNKNOWN",
    }
}

#[derive(Debug, Clone, Copy, Default)]
pub struct GrpcCallLayer;

impl<S> tower::Layer<S> for GrpcCallLayer {
    type Service = GrpcCalls<S>;

    fn layer(&self, inner: S) -> Self::Service {
        GrpcCalls { inner }
    }
}

#[derive(Debug, Clone)]
pub struct GrpcCalls<S> {
    inner: S,
}

/// `grpc-timeout`: at most 8 digits and a unit (H, M, S, m, u, n).
pub fn parse_grpc_timeout(value: &str) -> Option<Duration> {
    let (digits, unit) = value.split_at(value.len().checked_sub(1)?);
    if digits.is_empty() || digits.len() > 8 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let amount: u64 = digits.parse().ok()?;
    Some(match unit {
        "H" => Duration::from_secs(amount * 3600),
        "M" => Duration::from_secs(amount * 60),
        "S" => Duration::from_secs(amount),
        "m" => Duration::from_millis(amount),
        "u" => Duration::from_micros(amount),
        "n" => Duration::from_nanos(amount),
        _ => return None,
    })
}

impl<S, RequestBody> tower::Service<axum::http::Request<RequestBody>> for GrpcCalls<S>
where
    S: tower::Service<
            axum::http::Request<RequestBody>,
            Response = axum::http::Response<tonic::body::Body>,
        >,
    S::Future: Send + 'static,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = BoxFuture<'static, Result<Self::Response, Self::Error>>;

    fn poll_ready(&mut self, context: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(context)
    }

    fn call(&mut self, request: axum::http::Request<RequestBody>) -> Self::Future {
        let path = request.uri().path();
        let method = if KNOWN_SERVICES.iter().any(|prefix| path.starts_with(prefix)) {
            path.to_string()
        } else {
            "unknown".to_string()
        };
        let timeout = request
            .headers()
            .get("grpc-timeout")
            .and_then(|value| value.to_str().ok())
            .and_then(parse_grpc_timeout);
        let started = Instant::now();
        let response = self.inner.call(request);
        Box::pin(called_from("grpc", async move {
            let result = match timeout {
                None => response.await,
                Some(timeout) => {
                    let budget = timeout.saturating_sub(ahead_of_tonic(timeout));
                    let deadline = started + budget;
                    match tokio::time::timeout(budget, with_deadline(deadline, response)).await {
                        Ok(result) => result,
                        Err(_) => Ok(tonic::Status::deadline_exceeded(format!(
                            "the call's deadline ({timeout:?}) passed before the answer was ready"
                        ))
                        .into_http()),
                    }
                }
            };
            // Unary errors come as headers-only responses; a stream's final status is in its
            // trailers, after this layer, so it counts as `OK` here.
            let code = match &result {
                Ok(response) => code_name(
                    response
                        .headers()
                        .get("grpc-status")
                        .and_then(|value| value.to_str().ok()),
                ),
                Err(_) => "transport",
            };
            metrics::counter!("segsplat_grpc_requests_total", "method" => method.clone(),
                "code" => code)
            .increment(1);
            metrics::histogram!("segsplat_grpc_request_duration_seconds", "method" => method)
                .record(started.elapsed().as_secs_f64());
            result
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_labelled_by_their_canonical_names() {
        assert_eq!(code_name(None), "OK");
        assert_eq!(code_name(Some("0")), "OK");
        assert_eq!(code_name(Some("3")), "INVALID_ARGUMENT");
        assert_eq!(code_name(Some("5")), "NOT_FOUND");
        assert_eq!(code_name(Some("16")), "UNAUTHENTICATED");
        assert_eq!(code_name(Some("99")), "UNKNOWN");
        assert_eq!(code_name(Some("x")), "UNKNOWN");
    }

    #[test]
    fn grpc_timeouts_parse_by_the_spec() {
        assert_eq!(parse_grpc_timeout("5S"), Some(Duration::from_secs(5)));
        assert_eq!(parse_grpc_timeout("250m"), Some(Duration::from_millis(250)));
        assert_eq!(parse_grpc_timeout("1H"), Some(Duration::from_secs(3600)));
        assert_eq!(
            parse_grpc_timeout("99999999u"),
            Some(Duration::from_micros(99_999_999))
        );
        assert_eq!(parse_grpc_timeout("100n"), Some(Duration::from_nanos(100)));
        for bad in ["", "S", "5", "123456789S", "5s", "-5S", "5 S"] {
            assert_eq!(parse_grpc_timeout(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn the_own_timer_fires_ahead_of_tonics_by_a_bounded_margin() {
        assert_eq!(
            ahead_of_tonic(Duration::from_millis(3)),
            Duration::from_millis(1)
        );
        assert_eq!(
            ahead_of_tonic(Duration::from_millis(100)),
            Duration::from_millis(10)
        );
        assert_eq!(
            ahead_of_tonic(Duration::from_secs(30)),
            Duration::from_millis(20)
        );
    }
}
