//! Latency histograms of the use cases, labelled by the interface that called them (`api`:
//! `rest`, `grpc`, or `internal` for the CLI and embedders) and by `outcome` (`ok`, `error`).
//! The interface is a task-local the REST and gRPC layers set around their calls, so the use
//! cases keep one signature for every caller.

use std::future::Future;
use std::time::Instant;

tokio::task_local! {
    static INTERFACE: &'static str;
    static DEADLINE: Instant;
}

/// Runs `future` with a deadline (a gRPC client's `grpc-timeout`): work that has not started
/// by then is skipped ([`deadline_passed`]).
pub async fn with_deadline<F: Future>(deadline: Instant, future: F) -> F::Output {
    DEADLINE.scope(deadline, future).await
}

/// The current call's deadline, if its client set one; to carry into blocking work.
pub fn deadline() -> Option<Instant> {
    DEADLINE.try_with(|deadline| *deadline).ok()
}

/// Whether `deadline` (from [`deadline`]) has passed.
pub fn deadline_passed(deadline: Option<Instant>) -> bool {
    deadline.is_some_and(|deadline| Instant::now() >= deadline)
}

/// Runs `future` as a call from `interface` (`"rest"` or `"grpc"`).
pub async fn called_from<F: Future>(interface: &'static str, future: F) -> F::Output {
    INTERFACE.scope(interface, future).await
}

fn interface() -> &'static str {
    INTERFACE
        .try_with(|interface| *interface)
        .unwrap_or("internal")
}

/// Runs `call`, recording its duration in `histogram` with the interface and the outcome.
pub async fn timed<T, E>(
    histogram: &'static str,
    call: impl Future<Output = Result<T, E>>,
) -> Result<T, E> {
    let started = Instant::now();
    let result = call.await;
    metrics::histogram!(histogram, "api" => interface(),
        "outcome" => if result.is_ok() { "ok" } else { "error" })
    .record(started.elapsed().as_secs_f64());
    result
}
