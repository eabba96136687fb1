//! The moving, spinning spheres trained by a `segment_then_splat` job with the deformation field,
//! then asked about at held-out times: masks, positions, gRPC `ListObjects` with a time, the
//! scene's PLY and SPZ moved to a time, text queries at a time and a gRPC `StreamQuery` of
//! (pose, t) pairs.

use std::time::Duration;

use segsplat_api::proto;
use segsplat_engine::labels::read_labels;
use segsplat_engine::ply::read_ply;
use segsplat_scene::Level;
use segsplat_scene::synthetic_dynamic::{
    dynamic_frame_time, dynamic_object_center, dynamic_true_mask, dynamic_world_from_cameras,
    is_dynamic_test_frame,
};

use crate::common::TestService;
use crate::common::models_support::mask_iou;
use crate::support::{
    FRAMES, centroid_of, distance, get_ok, labelled_centroid, ply_header, png_bools, png_mask,
    pose_view_of, spec, upload_moving_spheres,
};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_moving_scene_is_segmented_and_queried_in_time() {
    let data = tempfile::tempdir().expect("tempdir");
    let Some(client) = TestService::start_with_tiny_models(data.path()).await else {
        return;
    };
    let scene_id = upload_moving_spheres(&client).await;

    // The deformation field, the scene's white background and user masks all come from the
    // scene, and the field's shape from the adapter; the schedule is shortened for the test.
    let job_id = client
        .create_job(
            &scene_id,
            "segment_then_splat",
            serde_json::json!({
                "steps": 1000, "checkpoint_every": 0, "random_init_count": 2000,
                "max_sh_degree": 1, "sh_degree_interval": 200, "densify_from": 100,
                "densify_until": 500, "opacity_reset_interval": 0, "max_gaussians": 6000,
                "background_shell": 200,
                "object_loss": {"middle_from": 1.0, "large_from": 1.0},
                "deformation": {"warm_up_steps": 200, "learning_rate_decay_steps": 40000}
            }),
        )
        .await;
    let job = client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(1200))
        .await;
    println!("job progress: {}", job["progress"]);
    let (_, metrics) = client
        .get_json(&format!("/v1/scenes/{scene_id}/trained/metrics.json"))
        .await;
    println!("metrics: {metrics}");
    let (_, objects) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects"))
        .await;
    for object in objects["objects"].as_array().into_iter().flatten() {
        println!(
            "object {} {}: {} Gaussians at {}",
            object["level"], object["object_id"], object["gaussian_count"], object["centroid"]
        );
    }
    let (status, header) = client
        .get_json(&format!("/v1/scenes/{scene_id}/trained/deformation.json"))
        .await;
    assert_eq!(status, 200, "{header}");
    // What trained is what the job says it ran: 4 x 64 on a software adapter, the released
    // 8 x 256 on a GPU.
    let software = segsplat_gpu::GpuContext::new_default()
        .map(|gpu| gpu.report.is_software)
        .unwrap_or(true);
    let (depth, width, skip_after) = if software { (4, 64, 2) } else { (8, 256, 4) };
    let field = &header["field"];
    let shape = |key: &str| field[key].as_u64();
    assert_eq!(
        (shape("depth"), shape("width"), shape("skip_after")),
        (Some(depth), Some(width), Some(skip_after)),
        "{header}"
    );
    assert_eq!(
        metrics["settings"]["deformation"]["field"], *field,
        "{metrics}"
    );

    // Masks at held-out frames (each renders at its frame's time). The scene lists Blender's
    // training frames before its test frames: find each synthetic frame by its file name.
    let poses = dynamic_world_from_cameras(&spec());
    let (status, cameras) = client
        .get_json(&format!("/v1/scenes/{scene_id}/trained/cameras.json"))
        .await;
    assert_eq!(status, 200, "{cameras}");
    let scene_index = |frame: usize| -> usize {
        let suffix = format!("/r_{frame}.png");
        cameras
            .as_array()
            .and_then(|cameras| {
                cameras.iter().position(|camera| {
                    camera["name"]
                        .as_str()
                        .is_some_and(|name| name.ends_with(&suffix))
                })
            })
            .unwrap_or_else(|| panic!("no camera for frame {frame}"))
    };
    let all_small = serde_json::json!([
        {"level": "small", "object_id": 1},
        {"level": "small", "object_id": 2},
        {"level": "small", "object_id": 3}
    ]);
    let mut frame_ious = Vec::new();
    for frame in (0..FRAMES).filter(|&i| is_dynamic_test_frame(i)) {
        let (status, body) = client
            .post_json(
                &format!("/v1/scenes/{scene_id}/masks"),
                serde_json::json!({"objects": all_small, "view": {"frame_index": scene_index(frame)},
                                   "visible_masks": true, "mask_format": "png"}),
            )
            .await;
        assert_eq!(status, 200, "{body}");
        let t = dynamic_frame_time(frame, FRAMES);
        let truth = dynamic_true_mask(&spec(), poses[frame], t, Level::Small);
        let mut ious = Vec::new();
        for (object, masks) in body["masks"].as_array().expect("masks").iter().enumerate() {
            let rendered = png_mask(masks["visible_mask"]["data"].as_str().expect("png"));
            let object_id = object as u32 + 1;
            let true_pixels: Vec<bool> = truth.iter().map(|&id| id == object_id).collect();
            if true_pixels.iter().any(|&inside| inside) {
                ious.push(mask_iou(&rendered.to_bools(), &true_pixels));
            }
        }
        println!("frame {frame} (t = {t:.2}): IoU {ious:.2?}");
        frame_ious.push(ious.iter().sum::<f64>() / ious.len().max(1) as f64);
    }
    let miou = frame_ious.iter().sum::<f64>() / frame_ious.len() as f64;
    println!("held-out mIoU {miou:.3} over {} frames", frame_ious.len());
    assert!(miou >= 0.6, "held-out mIoU {miou:.3}");

    // Centroids along the true paths at held-out times.
    let mut worst: f32 = 0.0;
    let mut errors = Vec::new();
    for frame in (0..FRAMES).filter(|&i| is_dynamic_test_frame(i)) {
        let t = dynamic_frame_time(frame, FRAMES);
        let (status, list) = client
            .get_json(&format!(
                "/v1/scenes/{scene_id}/objects?level=small&time={t}"
            ))
            .await;
        assert_eq!(status, 200, "{list}");
        for object in list["objects"].as_array().expect("objects") {
            let id = object["object_id"].as_u64().expect("id") as usize;
            let centroid: [f32; 3] =
                serde_json::from_value(object["centroid"].clone()).expect("centroid");
            let error = distance(centroid, dynamic_object_center(id - 1, t));
            worst = worst.max(error);
            errors.push(error);
        }
    }
    let mean = errors.iter().sum::<f32>() / errors.len() as f32;
    println!("centroid error at held-out times: mean {mean:.3}, worst {worst:.3}");
    assert!(
        mean < 0.12 && worst < 0.25,
        "centroids off their paths: mean {mean}, worst {worst}"
    );

    // The first object moves 0.7 along y over the sequence; its centroid must follow (the
    // sequence's ends are the field's least constrained times: more than half the way).
    let centroid_at = |list: &serde_json::Value| -> [f32; 3] {
        let object = list["objects"]
            .as_array()
            .and_then(|objects| objects.iter().find(|o| o["object_id"] == 1))
            .expect("object 1");
        centroid_of(object)
    };
    let (_, start) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects?level=small&time=0"))
        .await;
    let (_, end) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects?level=small&time=1"))
        .await;
    let moved = centroid_at(&end)[1] - centroid_at(&start)[1];
    assert!(moved > 0.4 && moved < 0.9, "object 1 moved {moved} along y");

    // The whole scene moved to a time (what a viewer's time slider downloads): the canonical
    // PLY's layout and Gaussian order, so labels.npy lines up and each object's Gaussians sit
    // where `objects?time=t` places it; only the geometry moves.
    let trained = format!("/v1/scenes/{scene_id}/trained");
    let canonical_bytes = get_ok(&client, &format!("{trained}/scene.ply")).await;
    let canonical = read_ply(canonical_bytes.as_slice()).expect("PLY").model;
    let labels = get_ok(&client, &format!("{trained}/labels.npy")).await;
    let labels = read_labels(labels.as_slice(), canonical.len()).expect("labels");
    let mut object_1_at = Vec::new();
    for time in [0.0, 0.5, 1.0] {
        let bytes = get_ok(&client, &format!("{trained}/scene.ply?time={time}")).await;
        assert_eq!(ply_header(&bytes), ply_header(&canonical_bytes));
        let at_time = read_ply(bytes.as_slice()).expect("PLY at a time").model;
        assert_eq!(at_time.len(), canonical.len());
        assert_eq!(at_time.opacity_logits, canonical.opacity_logits);
        assert_eq!(at_time.sh_coefficients, canonical.sh_coefficients);
        let (_, list) = client
            .get_json(&format!(
                "/v1/scenes/{scene_id}/objects?level=small&time={time}"
            ))
            .await;
        for object in list["objects"].as_array().expect("objects") {
            let id = object["object_id"].as_u64().expect("id") as u32;
            let mean = labelled_centroid(&at_time, &labels, Level::Small, id);
            let gap = distance(centroid_of(object), mean);
            assert!(
                gap < 1e-4,
                "t = {time}: object {id}'s Gaussians are {gap} off"
            );
        }
        object_1_at.push(labelled_centroid(&at_time, &labels, Level::Small, 1));
    }
    let ply_moved = object_1_at[2].y - object_1_at[0].y;
    println!("object 1's Gaussians in the PLY move {ply_moved:.3} along y from t = 0 to 1");
    assert!(ply_moved > 0.4, "object 1's Gaussians moved {ply_moved}");
    let spz_start = get_ok(&client, &format!("{trained}/scene.spz?time=0")).await;
    let spz_end = get_ok(&client, &format!("{trained}/scene.spz?time=1")).await;
    assert_ne!(spz_start, spz_end, "the SPZ moves too");
    for (asked, why) in [
        ("labels.npy?time=0.5", "a time with another file"),
        ("scene.ply?time=soon", "a time that is not a number"),
        ("scene.ply?time=2e6", "a time out of range"),
    ] {
        let (status, body) = client.get_json(&format!("{trained}/{asked}")).await;
        assert_eq!(status, 400, "{why}: {body}");
        assert_eq!(body["error"]["code"], "bad_request", "{why}: {body}");
    }

    // gRPC ListObjects at a time agrees with REST.
    let mut grpc = client.grpc().await;
    let listed = grpc
        .list_objects(proto::ListObjectsRequest {
            scene_id: scene_id.clone(),
            level: proto::Level::Small as i32,
            time: Some(1.0),
        })
        .await
        .expect("list")
        .into_inner();
    let grpc_centroid = listed
        .objects
        .iter()
        .find(|o| o.object_id == 1)
        .and_then(|o| o.centroid)
        .expect("centroid");
    let rest = centroid_at(&end);
    assert!((grpc_centroid.y - rest[1]).abs() < 1e-5);

    // gRPC tells a robot the scene is dynamic and each camera's normalised time.
    let described = grpc
        .get_scene(proto::GetSceneRequest {
            scene_id: scene_id.clone(),
        })
        .await
        .expect("scene")
        .into_inner();
    assert!(described.dynamic);
    assert!(described.time_count > 1, "{described:?}");
    let grpc_cameras = grpc
        .list_cameras(proto::ListCamerasRequest {
            scene_id: scene_id.clone(),
        })
        .await
        .expect("cameras")
        .into_inner()
        .cameras;
    let stored = cameras.as_array().expect("cameras.json is a list");
    assert_eq!(grpc_cameras.len(), stored.len());
    for (camera, json) in grpc_cameras.iter().zip(stored) {
        let time = camera.time.expect("a dynamic scene's frames have times");
        assert!((0.0..=1.0).contains(&time));
        assert!((time - json["time"].as_f64().unwrap()).abs() < 1e-6);
    }

    // gRPC RenderMask for a (pose, t) pair: a held-out frame's camera as a pose at that frame's
    // time gives the frame's mask; the same pose at another time does not.
    let frame = 19;
    let camera = &cameras[scene_index(frame)];
    let pose_view = |time: f64| proto::View {
        source: Some(proto::view::Source::Pose(pose_view_of(camera))),
        time: Some(time),
        max_side: None,
    };
    let mask_at = |object_id: u32, view: proto::View| {
        let mut grpc = grpc.clone();
        let scene_id = scene_id.clone();
        async move {
            let mask = grpc
                .render_mask(proto::RenderMaskRequest {
                    scene_id,
                    level: proto::Level::Small as i32,
                    object_id,
                    view: Some(view),
                    mask_encoding: proto::MaskEncoding::Png as i32,
                    visible_only: false,
                })
                .await
                .expect("render mask")
                .into_inner()
                .mask
                .expect("mask");
            png_bools(&mask.data)
        }
    };
    let t = f64::from(dynamic_frame_time(frame, FRAMES));
    let at_frame_time = mask_at(1, pose_view(t)).await;
    let (status, body) = client
        .post_json(
            &format!("/v1/scenes/{scene_id}/masks"),
            serde_json::json!({"objects": [{"level": "small", "object_id": 1}],
                               "view": {"frame_index": scene_index(frame)}, "mask_format": "png"}),
        )
        .await;
    assert_eq!(status, 200, "{body}");
    let rest = png_mask(body["masks"][0]["mask"]["data"].as_str().expect("png")).to_bools();
    assert_eq!(
        at_frame_time, rest,
        "a pose at the frame's time renders the frame's mask"
    );
    let at_start = mask_at(1, pose_view(0.0)).await;
    assert!(
        mask_iou(&at_start, &at_frame_time) < 0.9,
        "the object should have moved between t = 0 and t = {t}"
    );

    // Text queries at a time. The stand-in CLIP maps a crop's mean colour to the nearest colour
    // word: green and blue spheres read as "green" and "blue" (the red one's shaded two tones
    // average nearer "brown", so it is not asked for).
    let query_path = format!("/v1/scenes/{scene_id}/query");
    let query_at = |text: &str, time: f64| serde_json::json!({"text": text, "granularity": "small", "top_k": 1, "time": time});
    for (text, object_id) in [("green", 2), ("blue", 3)] {
        for time in [0.0, 0.5, 1.0] {
            let (status, answer) = client.post_json(&query_path, query_at(text, time)).await;
            assert_eq!(status, 200, "{answer}");
            let best = &answer["objects"][0];
            assert_eq!(best["object_id"], object_id, "{text:?} at {time}: {answer}");
            let (_, list) = client
                .get_json(&format!(
                    "/v1/scenes/{scene_id}/objects?level=small&time={time}"
                ))
                .await;
            let listed = list["objects"]
                .as_array()
                .and_then(|objects| objects.iter().find(|o| o["object_id"] == object_id))
                .expect("listed");
            let gap = distance(
                centroid_of(best),
                glam::Vec3::from_array(centroid_of(listed)),
            );
            assert!(
                gap < 1e-4,
                "a query at t places the object where the list at t does: {answer} {listed}"
            );
        }
    }
    // The green sphere swings 0.4 along -x between t = 0 and t = 1.
    let green_x = |answer: &serde_json::Value| centroid_of(&answer["objects"][0])[0];
    let (_, start) = client.post_json(&query_path, query_at("green", 0.0)).await;
    let (_, end) = client.post_json(&query_path, query_at("green", 1.0)).await;
    let swing = green_x(&end) - green_x(&start);
    assert!((-0.6..-0.2).contains(&swing), "green moved {swing} along x");
    // With a frame view, the query's time overrides the frame's own.
    let (status, answer) = client
        .post_json(
            &query_path,
            serde_json::json!({"text": "green", "granularity": "small", "time": 0.0,
                               "view": {"frame_index": scene_index(frame)}, "mask_format": "png"}),
        )
        .await;
    assert_eq!(status, 200, "{answer}");
    let queried = png_mask(answer["objects"][0]["mask"]["data"].as_str().expect("png"));
    assert_eq!(
        queried.to_bools(),
        mask_at(2, pose_view(0.0)).await,
        "the query's time, not the frame's"
    );

    // gRPC StreamQuery: (pose, t) pairs, and a time with no pose.
    let first = proto::StreamQueryRequest {
        scene_id: scene_id.clone(),
        text: "green".to_string(),
        granularity: proto::Granularity::Small as i32,
        top_k: 1,
        view: Some(pose_view_of(camera)),
        time: Some(t),
        mask_encoding: proto::MaskEncoding::Png as i32,
        sequence: 1,
    };
    let second = proto::StreamQueryRequest {
        scene_id: String::new(),
        text: String::new(),
        time: Some(0.0),
        sequence: 2,
        ..first.clone()
    };
    let third = proto::StreamQueryRequest {
        view: None,
        mask_encoding: proto::MaskEncoding::None as i32,
        time: Some(1.0),
        sequence: 3,
        ..second.clone()
    };
    let mut replies = grpc
        .clone()
        .stream_query(futures::stream::iter(vec![first, second, third]))
        .await
        .expect("stream")
        .into_inner();
    for (sequence, time) in [(1, Some(t)), (2, Some(0.0)), (3, None)] {
        let reply = replies.message().await.expect("reply").expect("a reply");
        assert_eq!(reply.sequence, sequence);
        let response = reply.response.expect("response");
        let best = &response.matches[0];
        let object = best.object.as_ref().expect("object");
        assert_eq!(object.object_id, 2, "{response:?}");
        match time {
            Some(time) => {
                let mask = best.mask.as_ref().expect("a mask for a pose");
                assert_eq!(
                    png_bools(&mask.data),
                    mask_at(2, pose_view(time)).await,
                    "message {sequence}: the mask at its own time"
                );
            }
            None => {
                assert!(best.mask.is_none(), "no pose, no mask");
                let centroid = object.centroid.expect("centroid");
                assert!(
                    (centroid.x - green_x(&end)).abs() < 1e-5,
                    "no pose: placed at the message's time"
                );
            }
        }
    }

    // A time that is not a number is refused.
    let (status, body) = client
        .post_json(
            &format!("/v1/scenes/{scene_id}/masks"),
            serde_json::json!({"objects": all_small, "view": {"frame_index": 3, "time": "soon"}}),
        )
        .await;
    assert!(status == 400 || status == 422, "{status}: {body}");
    client.shutdown().await;
}
