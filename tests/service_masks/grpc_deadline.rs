//! `RenderMask` over plain HTTP/2 with `grpc-timeout` set: the status the server itself answers,
//! with no client-side timer in between.

use segsplat_api::proto;

/// Calls RenderMask over plain HTTP/2 with `grpc-timeout` set and returns the `grpc-status` of
/// a headers-only answer (how the server answers an error), `None` for an answer with a body.
/// No timer on this side: what comes back is the server's answer.
pub(crate) async fn grpc_status_with_deadline(
    addr: std::net::SocketAddr,
    request: &proto::RenderMaskRequest,
    timeout: &str,
) -> Option<String> {
    use prost::Message;
    let message = request.encode_to_vec();
    // A gRPC frame: uncompressed, then the message's length, big-endian.
    let mut body = vec![0u8];
    body.extend_from_slice(&(message.len() as u32).to_be_bytes());
    body.extend_from_slice(&message);
    let http2 = reqwest::Client::builder()
        .http2_prior_knowledge()
        .build()
        .expect("HTTP/2 client");
    let response = http2
        .post(format!("http://{addr}/segsplat.v1.SceneQuery/RenderMask"))
        .header("content-type", "application/grpc")
        .header("te", "trailers")
        .header("grpc-timeout", timeout)
        .body(body)
        .send()
        .await
        .expect("an HTTP/2 answer");
    assert_eq!(response.status(), 200, "gRPC answers HTTP 200");
    response
        .headers()
        .get("grpc-status")
        .map(|value| value.to_str().expect("ASCII status").to_owned())
}
