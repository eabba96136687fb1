//! Request counts and latency of the gRPC API, by method: a tower layer around the tonic
//! server, so every service (SceneQuery, health, reflection) is measured the same way. The
//! latency is the time to the response's headers (for a stream, to its first message).

use std::task::{Context, Poll};
use std::time::Instant;

use futures::future::BoxFuture;

/// Methods outside these services are counted as `unknown`, so a client cannot grow the label
/// set with made-up paths.
const KNOWN_SERVICES: [&str; 4] = [
    "/segsplat.v1.",
    "/grpc.health.v1.",
    "/grpc.reflection.v1.",
    "/grpc.reflection.v1alpha.",
];

#[derive(Debug, Clone, Copy, Default)]
pub struct GrpcMetricsLayer;

impl<S> tower::Layer<S> for GrpcMetricsLayer {
    type Service = GrpcMetrics<S>;

    fn layer(&self, inner: S) -> Self::Service {
        GrpcMetrics { inner }
    }
}

#[derive(Debug, Clone)]
pub struct GrpcMetrics<S> {
    inner: S,
}

impl<S, RequestBody, ResponseBody> tower::Service<axum::http::Request<RequestBody>>
    for GrpcMetrics<S>
where
    S: tower::Service<
            axum::http::Request<RequestBody>,
            Response = axum::http::Response<ResponseBody>,
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
        let started = Instant::now();
        let response = self.inner.call(request);
        Box::pin(async move {
            let result = segsplat_service::usecases::observe::called_from("grpc", response).await;
            // Unary errors come as headers-only responses; a stream's final status is in its
            // trailers, after this layer, so it counts as `0` here.
            let code = match &result {
                Ok(response) => response
                    .headers()
                    .get("grpc-status")
                    .and_then(|value| value.to_str().ok())
                    .unwrap_or("0")
                    .to_string(),
                Err(_) => "transport".to_string(),
            };
            metrics::counter!("segsplat_grpc_requests_total", "method" => method.clone(),
                "code" => code)
            .increment(1);
            metrics::histogram!("segsplat_grpc_request_duration_seconds", "method" => method)
                .record(started.elapsed().as_secs_f64());
            result
        })
    }
}
