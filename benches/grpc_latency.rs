//! What a robot client sees over gRPC: latency of a `Query` that returns ids only, of a unary
//! `RenderMask` at 640x480, and of the same render inside a lock-step `StreamQuery`. A service
//! in this process (the stand-in CLIP models, the GPU adapter or lavapipe) trains a small
//! synthetic scene with `segment_then_splat`; then a client on a real TCP connection measures
//! `SEGSPLAT_BENCH_GRPC_CALLS` calls of each (default 40; the docs' figures use 300).
//!
//! Small unary replies stuck at 20-40 ms are the signature of Nagle's algorithm meeting delayed
//! ACKs; the listeners set TCP_NODELAY, and this is the figure that shows it.
//! Run: `SEGSPLAT_BENCH_GRPC_CALLS=300 cargo bench --bench grpc_latency` (docs/benchmarks.md).

#[path = "../tests/common/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use common::{TestService, archives};
use segsplat_api::proto;

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;

/// (p50, p99) in milliseconds.
fn percentiles(mut samples: Vec<Duration>) -> (f64, f64) {
    samples.sort();
    let at = |fraction: f64| {
        let index = ((samples.len() - 1) as f64 * fraction).round() as usize;
        samples[index].as_secs_f64() * 1000.0
    };
    (at(0.5), at(0.99))
}

/// A 640x480 view from the scene's first camera (focal length scaled with the width).
fn pose_view(camera: &serde_json::Value) -> Option<proto::PoseView> {
    let rows: Vec<f64> = camera["camera_to_world"]
        .as_array()?
        .iter()
        .flat_map(|row| row.as_array().into_iter().flatten())
        .filter_map(serde_json::Value::as_f64)
        .collect();
    let scale = f64::from(WIDTH) / camera["width"].as_f64()?;
    Some(proto::PoseView {
        pose: Some(proto::Pose {
            camera_to_world: rows,
        }),
        intrinsics: Some(proto::Intrinsics {
            fx: camera["fx"].as_f64()? * scale,
            fy: camera["fy"].as_f64()? * scale,
            cx: f64::from(WIDTH) / 2.0,
            cy: f64::from(HEIGHT) / 2.0,
            width: WIDTH,
            height: HEIGHT,
        }),
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let calls: usize = std::env::var("SEGSPLAT_BENCH_GRPC_CALLS")
        .ok()
        .and_then(|value| value.parse().ok())
        .unwrap_or(40);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async move {
        let data = tempfile::tempdir()?;
        let Some(service) = TestService::start_with_tiny_models(data.path()).await else {
            println!("grpc_latency: no GPU adapter or ONNX Runtime; skipped");
            return Ok(());
        };
        let archive = archives::queryable_scene_zip();
        let (status, scene) = service.upload(archive, "application/zip").await;
        if status != 201 {
            return Err(format!("upload: {status} {scene}").into());
        }
        let scene_id = scene["id"].as_str().ok_or("scene id")?.to_string();
        let job_id = service
            .create_job(
                &scene_id,
                "segment_then_splat",
                serde_json::json!({"steps": 60, "checkpoint_every": 0,
                                   "object_loss": {"objects_per_level": 1}}),
            )
            .await;
        service
            .wait_for_state(&job_id, "succeeded", Duration::from_secs(600))
            .await;
        let (_, cameras) = service
            .get_json(&format!("/v1/scenes/{scene_id}/trained/cameras.json"))
            .await;
        let view = pose_view(&cameras[0]).ok_or("cameras.json has no usable camera")?;
        let mut client = service.grpc().await;

        let query = proto::QueryRequest {
            scene_id: scene_id.clone(),
            text: "red".into(),
            granularity: proto::Granularity::Small as i32,
            top_k: 1,
            ..Default::default()
        };
        let render = proto::RenderMaskRequest {
            scene_id: scene_id.clone(),
            object_id: 1,
            level: proto::Level::Small as i32,
            view: Some(proto::View {
                source: Some(proto::view::Source::Pose(view.clone())),
                time: None,
                max_side: None,
            }),
            mask_encoding: proto::MaskEncoding::Png as i32,
            visible_only: false,
        };
        // Warm the scene cache, the text encoder and the connection.
        for _ in 0..3 {
            client.query(query.clone()).await?;
            client.render_mask(render.clone()).await?;
        }
        let mut query_times = Vec::new();
        for _ in 0..calls {
            let started = Instant::now();
            client.query(query.clone()).await?;
            query_times.push(started.elapsed());
        }
        let mut render_times = Vec::new();
        for _ in 0..calls {
            let started = Instant::now();
            client.render_mask(render.clone()).await?;
            render_times.push(started.elapsed());
        }
        let stream_request = |sequence: u64| proto::StreamQueryRequest {
            scene_id: scene_id.clone(),
            text: "red".into(),
            granularity: proto::Granularity::Small as i32,
            top_k: 1,
            view: Some(view.clone()),
            time: None,
            mask_encoding: proto::MaskEncoding::Png as i32,
            sequence,
        };
        // Lock-step stream: the next pose goes out when the previous answer is in.
        let (sender, receiver) = tokio::sync::mpsc::channel(1);
        let mut replies = client
            .stream_query(tokio_stream::wrappers::ReceiverStream::new(receiver))
            .await?
            .into_inner();
        let mut stream_times = Vec::new();
        for sequence in 0..(calls + 3) as u64 {
            let started = Instant::now();
            sender.send(stream_request(sequence)).await?;
            replies.message().await?.ok_or("the stream ended")?;
            if sequence >= 3 {
                stream_times.push(started.elapsed());
            }
        }
        drop(sender);
        // Pipelined stream: every pose sent at once; the server answers several at a time.
        let requests: Vec<_> = (0..calls as u64).map(stream_request).collect();
        let started = Instant::now();
        let mut replies = client
            .stream_query(tokio_stream::iter(requests))
            .await?
            .into_inner();
        let mut received = 0;
        while let Some(reply) = replies.message().await? {
            if reply.sequence != received {
                return Err(format!("reply {} came before {received}", reply.sequence).into());
            }
            received += 1;
        }
        let pipelined_rate = received as f64 / started.elapsed().as_secs_f64();
        let lock_step_rate =
            stream_times.len() as f64 / stream_times.iter().map(Duration::as_secs_f64).sum::<f64>();
        let (query_p50, query_p99) = percentiles(query_times);
        let (render_p50, render_p99) = percentiles(render_times);
        let (stream_p50, stream_p99) = percentiles(stream_times);
        println!(
            "grpc_latency ({calls} calls each, {}): Query ids only p50 {query_p50:.2} ms p99 \
             {query_p99:.2} ms; RenderMask {WIDTH}x{HEIGHT} p50 {render_p50:.2} ms p99 \
             {render_p99:.2} ms; StreamQuery with a {WIDTH}x{HEIGHT} mask p50 {stream_p50:.2} ms \
             p99 {stream_p99:.2} ms; unary/stream p50 {:.2}; StreamQuery lock-step \
             {lock_step_rate:.1} msg/s, pipelined {pipelined_rate:.1} msg/s ({:.2}x)",
            segsplat_gpu::GpuContext::new_default()
                .map_or("no adapter".to_string(), |gpu| gpu.report.name),
            render_p50 / stream_p50,
            pipelined_rate / lock_step_rate,
        );
        service.shutdown().await;
        Ok(())
    })
}
