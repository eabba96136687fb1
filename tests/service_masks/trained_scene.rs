//! One trained three-sphere scene asked through REST and gRPC for every mask and export a caller
//! has: masks for a frame and for a pose, visible-only masks, the PNG endpoint, per-object PLY,
//! the labels sidecar, `RenderMask`, and the errors a caller can act on.

use std::time::Duration;

use segsplat_api::proto;
use segsplat_engine::labels::read_labels;
use segsplat_engine::ply::read_ply;
use segsplat_scene::Level;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::SyntheticSpec;

use crate::common::{TestService, archives};
use crate::grpc_deadline::grpc_status_with_deadline;
use crate::local_commands::local_commands_read_the_service_data;
use crate::truth::{decode_mask, png_mask, true_mask};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn masks_and_exports_of_a_trained_scene() {
    let data = tempfile::tempdir().unwrap();
    let Some(client) =
        TestService::start_on_gpu(data.path(), |config| config.query.max_mask_side = 4096).await
    else {
        return;
    };
    let spec = SyntheticSpec {
        frame_count: 12,
        width: 80,
        height: 60,
        with_masks: Some(Level::ALL.to_vec()),
        ..SyntheticSpec::default()
    };
    let files = archives::colmap_files(spec, ColmapEncoding::Text);
    let (status, scene) = client
        .upload(archives::zip_of(&files), "application/zip")
        .await;
    assert_eq!(status, 201, "{scene}");
    let scene_id = scene["id"].as_str().unwrap().to_string();
    let masks_path = format!("/v1/scenes/{scene_id}/masks");
    let small_one = serde_json::json!([{"level": "small", "object_id": 1}]);
    let request = |objects: &serde_json::Value, view: serde_json::Value| serde_json::json!({"objects": objects, "view": view, "visible_masks": true});

    let (status, body) = client
        .post_json(
            &masks_path,
            request(&small_one, serde_json::json!({"frame_index": 0})),
        )
        .await;
    assert_eq!(status, 409, "nothing trained yet: {body}");
    let (status, body) = client
        .get_bytes(&format!("/v1/scenes/{scene_id}/trained/scene.ply"))
        .await;
    assert_eq!(status, 409, "{}", String::from_utf8_lossy(&body));

    let job_id = client
        .create_job(
            &scene_id,
            "segment_then_splat",
            serde_json::json!({"steps": 150, "checkpoint_every": 0, "densify_from": 50,
                               "densify_interval": 50, "densify_until": 120}),
        )
        .await;
    client
        .wait_for_state(&job_id, "succeeded", Duration::from_secs(600))
        .await;

    // Frame views: every small object's visible mask against the true silhouette.
    let (status, cameras) = client
        .get_json(&format!("/v1/scenes/{scene_id}/trained/cameras.json"))
        .await;
    assert_eq!(status, 200, "{cameras}");
    let cameras = cameras.as_array().unwrap().clone();
    assert_eq!(cameras.len(), 12);
    let all_small = serde_json::json!([
        {"level": "small", "object_id": 1},
        {"level": "small", "object_id": 2},
        {"level": "small", "object_id": 3}
    ]);
    let mut ious = Vec::new();
    for frame_index in [1usize, 6, 10] {
        let (status, answer) = client
            .post_json(
                &masks_path,
                request(&all_small, serde_json::json!({"frame_index": frame_index})),
            )
            .await;
        assert_eq!(status, 200, "{answer}");
        let frame_name = cameras[frame_index]["name"].as_str().unwrap();
        for rendered in answer["masks"].as_array().unwrap() {
            let object_id = rendered["object_id"].as_u64().unwrap() as u32;
            let full = decode_mask(&rendered["mask"]);
            let visible = decode_mask(&rendered["visible_mask"]);
            assert_eq!((full.width(), full.height()), (80, 60));
            assert_eq!(
                visible.intersection_area(&full).unwrap(),
                visible.area(),
                "visible lies inside the full mask"
            );
            let truth = true_mask(&files, Level::Small, frame_name, object_id);
            if truth.area() > 0 {
                ious.push(visible.iou(&truth).unwrap());
            }
        }
    }
    let mean_iou = ious.iter().sum::<f32>() / ious.len() as f32;
    println!(
        "visible-mask IoU against the truth over {} masks: mean {mean_iou:.3} {ious:?}",
        ious.len()
    );
    assert!(mean_iou >= 0.7, "{ious:?}");

    // The same camera given as a pose renders the same mask; max_side scales it.
    let camera = &cameras[6];
    let pose_view = serde_json::json!({
        "camera_to_world": camera["camera_to_world"],
        "intrinsics": {"fx": camera["fx"], "fy": camera["fy"], "cx": camera["cx"],
                       "cy": camera["cy"], "width": camera["width"], "height": camera["height"]}
    });
    let (status, by_pose) = client
        .post_json(&masks_path, request(&small_one, pose_view.clone()))
        .await;
    assert_eq!(status, 200, "{by_pose}");
    let (_, by_frame) = client
        .post_json(
            &masks_path,
            request(&small_one, serde_json::json!({"frame_index": 6})),
        )
        .await;
    assert_eq!(
        decode_mask(&by_pose["masks"][0]["mask"]),
        decode_mask(&by_frame["masks"][0]["mask"])
    );
    let (status, half) = client
        .post_json(
            &masks_path,
            serde_json::json!({"objects": small_one, "view": {"frame_index": 6, "max_side": 40},
                               "mask_format": "png"}),
        )
        .await;
    assert_eq!(status, 200, "{half}");
    assert_eq!(half["masks"][0]["mask"]["format"], "png");
    assert_eq!(decode_mask(&half["masks"][0]["mask"]).width(), 40);
    assert!(half["masks"][0].get("visible_mask").is_none());

    // A mask at the service's largest side: 4096 x 3072 RGBA f32 needs more than one storage
    // binding holds on the software adapter (128 MiB), so it is rendered in bands of rows. Its
    // pixels agree with the frame-sized mask at the matching pixel centres.
    let scale = 4096.0 / camera["width"].as_f64().unwrap();
    let mut large_view = pose_view.clone();
    for key in ["fx", "fy", "cx", "cy"] {
        large_view["intrinsics"][key] = serde_json::json!(camera[key].as_f64().unwrap() * scale);
    }
    large_view["intrinsics"]["width"] = serde_json::json!(4096);
    large_view["intrinsics"]["height"] = serde_json::json!(3072);
    let (status, large) = client
        .post_json(
            &masks_path,
            serde_json::json!({"objects": small_one, "view": large_view, "mask_format": "png"}),
        )
        .await;
    assert_eq!(status, 200, "{large}");
    let large = decode_mask(&large["masks"][0]["mask"]);
    assert_eq!((large.width(), large.height()), (4096, 3072));
    let small = decode_mask(&by_frame["masks"][0]["mask"]);
    let mut agree = 0;
    for v in 0..small.height() {
        for u in 0..small.width() {
            let big_u = ((f64::from(u) + 0.5) * scale) as u32;
            let big_v = ((f64::from(v) + 0.5) * scale) as u32;
            agree += usize::from(small.get(u, v) == large.get(big_u, big_v));
        }
    }
    let pixels = (small.width() * small.height()) as usize;
    assert!(
        agree * 100 >= pixels * 97,
        "{agree} of {pixels} pixels agree"
    );

    // The PNG endpoint.
    let (status, png) = client
        .get_bytes(&format!(
            "/v1/scenes/{scene_id}/objects/small/1/mask.png?frame_index=6"
        ))
        .await;
    assert_eq!(status, 200);
    assert_eq!(png_mask(&png), decode_mask(&by_frame["masks"][0]["mask"]));

    // Errors a caller can act on.
    let bad = [
        (
            request(&small_one, serde_json::json!({"frame_index": 12})),
            400,
            "frame 12",
        ),
        (
            request(&small_one, serde_json::json!({})),
            400,
            "frame_index",
        ),
        (
            request(
                &serde_json::json!([{"level": "small", "object_id": 99}]),
                serde_json::json!({"frame_index": 0}),
            ),
            404,
            "small object 99",
        ),
        (
            request(
                &serde_json::json!([{"level": "tiny", "object_id": 1}]),
                serde_json::json!({"frame_index": 0}),
            ),
            400,
            "level",
        ),
        (
            request(
                &small_one,
                serde_json::json!({"frame_index": 0, "max_side": 0}),
            ),
            400,
            "max_side",
        ),
        (
            request(&small_one, {
                let mut view = pose_view.clone();
                view["camera_to_world"][0][0] = serde_json::json!(3.0);
                view
            }),
            400,
            "rigid",
        ),
        (
            request(&small_one, {
                let mut view = pose_view.clone();
                view["intrinsics"]["width"] = serde_json::json!(5000);
                view
            }),
            400,
            "4096",
        ),
    ];
    for (body, expected_status, words) in bad {
        let (status, answer) = client.post_json(&masks_path, body.clone()).await;
        assert_eq!(status, expected_status, "{body} -> {answer}");
        assert!(answer.to_string().contains(words), "{body} -> {answer}");
    }
    let (status, _) = client
        .post_json(
            "/v1/scenes/nope/masks",
            request(&small_one, serde_json::json!({"frame_index": 0})),
        )
        .await;
    assert_eq!(status, 404);

    // Exports: the whole scene, the labels sidecar in PLY order, one object's PLY.
    let (status, ply) = client
        .get_bytes(&format!("/v1/scenes/{scene_id}/trained/scene.ply"))
        .await;
    assert_eq!(status, 200);
    let scene_model = read_ply(ply.as_slice()).unwrap().model;
    let (status, labels) = client
        .get_bytes(&format!("/v1/scenes/{scene_id}/trained/labels.npy"))
        .await;
    assert_eq!(status, 200);
    let labels = read_labels(labels.as_slice(), scene_model.len()).unwrap();
    let in_object = labels
        .iter()
        .filter(|ids| ids[Level::Middle.index()] == 1)
        .count();
    let (status, object_ply) = client
        .get_bytes(&format!("/v1/scenes/{scene_id}/objects/middle/1/ply"))
        .await;
    assert_eq!(status, 200);
    let object = read_ply(object_ply.as_slice()).unwrap().model;
    assert_eq!(object.len(), in_object);
    assert!(in_object > 0);
    let (status, objects) = client
        .get_json(&format!("/v1/scenes/{scene_id}/objects?level=middle"))
        .await;
    assert_eq!(status, 200);
    assert_eq!(
        objects["objects"][0]["gaussian_count"], in_object as u64,
        "{objects}"
    );
    // The same as compressed SPZ, read by a reader the project did not write (`spz_rs`).
    let (status, scene_spz) = client
        .get_bytes(&format!("/v1/scenes/{scene_id}/trained/scene.spz"))
        .await;
    assert_eq!(status, 200);
    let packed = spz_rs::load_packed_gaussians_from_spz_buffer(scene_spz.as_slice()).unwrap();
    assert_eq!(packed.num_points, scene_model.len());
    assert!(
        scene_spz.len() * 4 < ply.len(),
        "{} vs {}",
        scene_spz.len(),
        ply.len()
    );
    let (status, object_spz) = client
        .get_bytes(&format!("/v1/scenes/{scene_id}/objects/middle/1/spz"))
        .await;
    assert_eq!(status, 200);
    let packed = spz_rs::load_packed_gaussians_from_spz_buffer(object_spz.as_slice()).unwrap();
    assert_eq!(packed.num_points, in_object);
    for (path, expected) in [
        (format!("/v1/scenes/{scene_id}/objects/middle/77/spz"), 404),
        (format!("/v1/scenes/{scene_id}/trained/secrets.txt"), 404),
        (format!("/v1/scenes/{scene_id}/objects/middle/77/ply"), 404),
        (format!("/v1/scenes/{scene_id}/objects/huge/1/ply"), 400),
    ] {
        let (status, body) = client.get_bytes(&path).await;
        assert_eq!(
            status,
            expected,
            "{path}: {}",
            String::from_utf8_lossy(&body)
        );
    }

    // gRPC has what a robot needs to pick a view: the cameras (as `cameras.json`) and the
    // scene's frame sizes and time facts.
    let mut grpc = client.grpc().await;
    let listed = grpc
        .list_cameras(proto::ListCamerasRequest {
            scene_id: scene_id.clone(),
        })
        .await
        .unwrap()
        .into_inner()
        .cameras;
    let stored = &cameras;
    assert_eq!(listed.len(), stored.len());
    for (index, (camera, json)) in listed.iter().zip(stored).enumerate() {
        assert_eq!(camera.frame_index as usize, index);
        assert_eq!(camera.name, json["name"].as_str().unwrap());
        let intrinsics = camera.intrinsics.as_ref().unwrap();
        assert_eq!((intrinsics.width, intrinsics.height), (80, 60));
        assert_eq!(intrinsics.fx, json["fx"].as_f64().unwrap());
        let pose = &camera.pose.as_ref().unwrap().camera_to_world;
        // Stored as f32: the gRPC doubles are those f32 values exactly.
        let json_pose: Vec<f32> = json["camera_to_world"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|row| row.as_array().unwrap().iter())
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        let grpc_pose: Vec<f32> = pose.iter().map(|&v| v as f32).collect();
        assert_eq!(grpc_pose, json_pose);
        assert_eq!(camera.time, None, "a static scene's frames have no time");
    }
    let described = grpc
        .get_scene(proto::GetSceneRequest {
            scene_id: scene_id.clone(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        (
            described.dynamic,
            described.time_count,
            described.resolutions
        ),
        (
            false,
            0,
            vec![proto::FrameSize {
                width: 80,
                height: 60
            }]
        )
    );
    let unknown = grpc
        .list_cameras(proto::ListCamerasRequest {
            scene_id: "no-such-scene".into(),
        })
        .await
        .unwrap_err();
    assert_eq!(unknown.code(), tonic::Code::NotFound, "{unknown}");

    // gRPC RenderMask: the same mask as REST, as PNG bytes.
    let frame_view = proto::View {
        source: Some(proto::view::Source::FrameIndex(6)),
        time: None,
        max_side: None,
    };
    let render_request = |object_id: u32, encoding: proto::MaskEncoding, visible_only: bool| {
        proto::RenderMaskRequest {
            scene_id: scene_id.clone(),
            object_id,
            level: proto::Level::Small as i32,
            view: Some(frame_view.clone()),
            mask_encoding: encoding as i32,
            visible_only,
        }
    };
    let rendered = grpc
        .render_mask(render_request(1, proto::MaskEncoding::Png, false))
        .await
        .unwrap()
        .into_inner();
    let mask = rendered.mask.unwrap();
    assert!(mask.amodal);
    assert_eq!(
        png_mask(&mask.data),
        decode_mask(&by_frame["masks"][0]["mask"])
    );
    let missing = grpc
        .render_mask(render_request(99, proto::MaskEncoding::CocoRle, true))
        .await
        .unwrap_err();
    assert_eq!(missing.code(), tonic::Code::NotFound, "{missing}");
    // RenderMask's answer is a mask: "no mask" is refused, not answered in some other encoding.
    let no_encoding = grpc
        .render_mask(render_request(1, proto::MaskEncoding::None, false))
        .await
        .unwrap_err();
    assert_eq!(
        no_encoding.code(),
        tonic::Code::InvalidArgument,
        "{no_encoding}"
    );
    assert!(
        no_encoding.message().contains("mask_encoding"),
        "{no_encoding}"
    );
    // Deadlines: a call whose `grpc-timeout` passes is answered DEADLINE_EXCEEDED by the
    // server, never CANCELLED. Sent over plain HTTP/2, not tonic's client: that one enforces the
    // header with a timer of its own, which on a busy machine fired before the server's answer
    // arrived every time (all nine calls of a CI run), so the server's answer went unseen.
    let grpc_addr = client.service.grpc_addr().expect("gRPC address");
    for timeout in ["1m", "1m", "1m"] {
        let request = render_request(1, proto::MaskEncoding::Png, false);
        let status = grpc_status_with_deadline(grpc_addr, &request, timeout).await;
        assert_eq!(
            status.as_deref(),
            Some("4"),
            "{timeout}: the server's grpc-status (4 is DEADLINE_EXCEEDED)"
        );
    }
    let cache = client.service.serving_stats();
    assert_eq!(cache.loads, 1, "one load, then cache hits: {cache:?}");
    assert!(cache.hits >= 10, "{cache:?}");
    client.shutdown().await;

    local_commands_read_the_service_data(data.path(), &scene_id, &files, &cameras, in_object);
}
