//! A `segment_then_splat` scene embedded and asked in words: text queries, streamed queries per
//! pose, and views refused when nothing matches.

use crate::common::{TestService, archives};
use crate::support::run_short_segment_then_splat;

/// The ONNX Runtime library can be loaded, or the test may be skipped (`SEGSPLAT_SKIP_ORT_TESTS=1`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn segment_then_splat_embeds_objects_and_answers_text_queries() {
    let data = tempfile::tempdir().unwrap();
    let models = crate::common::tiny_models_dir();
    let Some(client) = TestService::start_with_tiny_models(data.path()).await else {
        return;
    };
    let archive = archives::queryable_scene_zip();
    let (status, scene) = client.upload(archive, "application/zip").await;
    assert_eq!(status, 201, "{scene}");
    let scene_id = scene["id"].as_str().unwrap();
    let query_path = format!("/v1/scenes/{scene_id}/query");
    let query = |text: &str, granularity: &str| serde_json::json!({"text": text, "granularity": granularity, "top_k": 3});

    let (status, body) = client.post_json(&query_path, query("red", "small")).await;
    assert_eq!(status, 409, "nothing trained yet: {body}");
    let (status, body) = client.post_json(&query_path, query("red", "tiny")).await;
    assert_eq!(status, 400, "{body}");
    let (status, body) = client
        .post_json(&query_path, serde_json::json!({"text": "red", "top_k": 0}))
        .await;
    assert_eq!(status, 400, "{body}");
    let (status, body) = client
        .post_json("/v1/scenes/nope/query", query("red", "small"))
        .await;
    assert_eq!(status, 404, "{body}");

    let (_, job) = run_short_segment_then_splat(&client, scene_id).await;
    assert_eq!(
        job["progress"]["metrics"]["embeddings"], 6.0,
        "every object (3 small, 2 middle, 1 large) is embedded: {job}"
    );

    for (text, expected) in [("red", 1), ("a red mug", 1), ("green", 2), ("blue", 3)] {
        let (status, answer) = client.post_json(&query_path, query(text, "small")).await;
        assert_eq!(status, 200, "{answer}");
        println!("{text:?} (small): {answer}");
        assert_eq!(answer["matched"], true, "{text:?}: {answer}");
        let best = &answer["objects"][0];
        assert_eq!(best["level"], "small", "{text:?}: {answer}");
        assert_eq!(best["object_id"], expected, "{text:?}: {answer}");
        assert!(best["relevancy"].as_f64().unwrap() >= 0.55, "{answer}");
        assert!(best["bounds_max"][0].as_f64() >= best["bounds_min"][0].as_f64());
    }
    for granularity in ["small", "auto", "large"] {
        let (status, answer) = client
            .post_json(&query_path, query("a chair", granularity))
            .await;
        assert_eq!(status, 200, "{answer}");
        println!("\"a chair\" ({granularity}): {answer}");
        assert_eq!(answer["matched"], false, "{granularity}: {answer}");
        assert!(answer["objects"].as_array().unwrap().is_empty());
    }
    let (status, lenient) = client
        .post_json(
            &query_path,
            serde_json::json!({"text": "a chair", "granularity": "small", "threshold": 0.0}),
        )
        .await;
    assert_eq!(status, 200);
    println!("\"a chair\" (small, threshold 0): {lenient}");
    assert_eq!(
        lenient["matched"], true,
        "the threshold is the caller's: {lenient}"
    );

    // With a view, each match carries its masks.
    let (status, with_masks) = client
        .post_json(
            &query_path,
            serde_json::json!({"text": "green", "granularity": "small",
                               "view": {"frame_index": 0, "max_side": 48},
                               "mask_format": "png", "visible_masks": true}),
        )
        .await;
    assert_eq!(status, 200, "{with_masks}");
    let best = &with_masks["objects"][0];
    assert_eq!(best["object_id"], 2, "{with_masks}");
    assert_eq!(
        (
            &best["mask"]["format"],
            &best["mask"]["width"],
            &best["mask"]["height"]
        ),
        (
            &serde_json::json!("png"),
            &serde_json::json!(48),
            &serde_json::json!(36)
        ),
        "{with_masks}"
    );
    assert!(best["visible_mask"]["data"].is_string(), "{with_masks}");
    let (status, body) = client
        .post_json(
            &query_path,
            serde_json::json!({"text": "green", "granularity": "small",
                               "view": {"frame_index": 99}}),
        )
        .await;
    assert_eq!(status, 400, "{body}");

    stream_query_answers_each_pose(&client, scene_id).await;
    bad_views_are_refused_when_nothing_matches(&client, scene_id).await;
    client.shutdown().await;

    // `segsplat query` on the same data dir: the answer as JSON, masks as PNGs.
    let out = data.path().join("masks");
    let output = std::process::Command::new(crate::common::segsplat_bin::segsplat_bin())
        .args([
            "query",
            scene_id,
            "blue",
            "--granularity",
            "small",
            "--frame",
            "0",
        ])
        .args(["--frame", "4", "--visible", "--data-dir"])
        .arg(data.path())
        .arg("--out")
        .arg(&out)
        .env("SEGSPLAT_MODELS__DIR", &models)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    let answer: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(answer["matched"], true, "{answer}");
    assert_eq!(answer["objects"][0]["object_id"], 3, "{answer}");
    let written = answer["objects"][0]["masks"].as_array().unwrap();
    assert_eq!(
        written.len(),
        4,
        "full and visible for two frames: {answer}"
    );
    let mask = image::open(out.join("0-small-3-frame4.png"))
        .unwrap()
        .into_luma8();
    assert_eq!(mask.dimensions(), (96, 72));
    assert!(mask.pixels().any(|pixel| pixel.0[0] == 255));
}

/// gRPC `StreamQuery`: the text is sent once, then poses; each reply echoes its sequence and
/// carries the mask for that pose; a bad pose ends the stream with INVALID_ARGUMENT.
async fn stream_query_answers_each_pose(client: &TestService, scene_id: &str) {
    use segsplat_api::proto;
    let (status, cameras) = client
        .get_json(&format!("/v1/scenes/{scene_id}/trained/cameras.json"))
        .await;
    assert_eq!(status, 200, "{cameras}");
    let pose_view = |index: usize| {
        let camera = &cameras[index];
        let rows: Vec<f64> = camera["camera_to_world"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|row| row.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
            .collect();
        proto::PoseView {
            pose: Some(proto::Pose {
                camera_to_world: rows,
            }),
            intrinsics: Some(proto::Intrinsics {
                fx: camera["fx"].as_f64().unwrap(),
                fy: camera["fy"].as_f64().unwrap(),
                cx: camera["cx"].as_f64().unwrap(),
                cy: camera["cy"].as_f64().unwrap(),
                width: camera["width"].as_u64().unwrap() as u32,
                height: camera["height"].as_u64().unwrap() as u32,
            }),
        }
    };
    let first = proto::StreamQueryRequest {
        scene_id: scene_id.to_string(),
        text: "blue".to_string(),
        granularity: proto::Granularity::Small as i32,
        top_k: 1,
        view: Some(pose_view(0)),
        time: None,
        mask_encoding: proto::MaskEncoding::CocoRle as i32,
        sequence: 10,
    };
    let second = proto::StreamQueryRequest {
        scene_id: String::new(),
        text: String::new(),
        view: Some(pose_view(3)),
        sequence: 11,
        ..first.clone()
    };
    let mut broken = second.clone();
    broken.sequence = 12;
    if let Some(pose) = broken.view.as_mut().and_then(|view| view.pose.as_mut()) {
        pose.camera_to_world.truncate(12);
    }
    let mut grpc = client.grpc().await;
    let mut replies = grpc
        .stream_query(futures::stream::iter(vec![first, second, broken]))
        .await
        .unwrap()
        .into_inner();
    for expected_sequence in [10, 11] {
        let reply = replies.message().await.unwrap().unwrap();
        assert_eq!(reply.sequence, expected_sequence);
        let response = reply.response.unwrap();
        assert!(!response.no_match, "{response:?}");
        let best = &response.matches[0];
        assert_eq!(best.object.as_ref().unwrap().object_id, 3, "{response:?}");
        let mask = best.mask.as_ref().unwrap();
        assert_eq!((mask.width, mask.height), (96, 72));
        assert!(mask.amodal && !mask.data.is_empty());
    }
    let error = replies.message().await.unwrap_err();
    assert_eq!(error.code(), tonic::Code::InvalidArgument, "{error}");
    assert!(error.message().contains("16 values"), "{error}");
}

/// A query whose text matches nothing still has its view checked (issue 41): a pose that is not
/// rigid, or a frame the scene lacks, is a bad request (REST 400, gRPC INVALID_ARGUMENT), not
/// "no match"; a good view with the same text is answered "no match".
async fn bad_views_are_refused_when_nothing_matches(client: &TestService, scene_id: &str) {
    use segsplat_api::proto;
    let query_path = format!("/v1/scenes/{scene_id}/query");
    let intrinsics = serde_json::json!({"fx": 80.0, "fy": 80.0, "cx": 48.0, "cy": 36.0, "width": 96, "height": 72});
    let scaled = serde_json::json!([[2.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1]]);
    let identity =
        serde_json::json!([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1]]);
    let asked = |view: serde_json::Value| serde_json::json!({"text": "a chair", "granularity": "small", "view": view});
    for (view, mentions) in [
        (
            serde_json::json!({"camera_to_world": scaled, "intrinsics": intrinsics}),
            "rigid",
        ),
        (serde_json::json!({"frame_index": 900}), "900"),
    ] {
        let (status, body) = client.post_json(&query_path, asked(view)).await;
        assert_eq!(status, 400, "{body}");
        assert!(
            body["error"]["message"]
                .as_str()
                .unwrap()
                .contains(mentions),
            "{body}"
        );
    }
    let good = serde_json::json!({"camera_to_world": identity, "intrinsics": intrinsics});
    let (status, body) = client.post_json(&query_path, asked(good)).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["matched"], false, "{body}");

    let mut grpc = client.grpc().await;
    let request = |rows: Vec<f64>| proto::QueryRequest {
        scene_id: scene_id.to_string(),
        text: "a chair".to_string(),
        granularity: proto::Granularity::Small as i32,
        top_k: 1,
        view: Some(proto::View {
            source: Some(proto::view::Source::Pose(proto::PoseView {
                pose: Some(proto::Pose {
                    camera_to_world: rows,
                }),
                intrinsics: Some(proto::Intrinsics {
                    fx: 80.0,
                    fy: 80.0,
                    cx: 48.0,
                    cy: 36.0,
                    width: 96,
                    height: 72,
                }),
            })),
            ..Default::default()
        }),
        mask_encoding: proto::MaskEncoding::Png as i32,
        ..Default::default()
    };
    let mut rows = vec![0.0; 16];
    for (index, value) in [(0, 2.0), (5, 1.0), (10, 1.0), (15, 1.0)] {
        rows[index] = value;
    }
    let refused = grpc.query(request(rows.clone())).await.unwrap_err();
    assert_eq!(refused.code(), tonic::Code::InvalidArgument, "{refused}");
    assert!(refused.message().contains("rigid"), "{refused}");
    rows[0] = 1.0;
    let answered = grpc.query(request(rows)).await.unwrap().into_inner();
    assert!(answered.no_match, "{answered:?}");
}
