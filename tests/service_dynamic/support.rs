//! What the dynamic-scene tests share: the synthetic moving scene's spec, its upload, and reading
//! masks, centroids, pose views and PLY headers from the service's answers.

use base64::Engine;
use segsplat_api::proto;
use segsplat_engine::GaussianModel;
use segsplat_scene::Level;
use segsplat_scene::synthetic::SyntheticSpec;
use segsplat_vision::segment::BitMask;

use crate::common::{TestService, archives};

pub(crate) const FRAMES: usize = 40;

pub(crate) fn spec() -> SyntheticSpec {
    SyntheticSpec {
        frame_count: FRAMES,
        width: 64,
        height: 48,
        with_masks: Some(Level::ALL.to_vec()),
        ..SyntheticSpec::default()
    }
}

pub(crate) fn png_mask(data: &str) -> BitMask {
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(data)
        .expect("base64");
    let image = image::load_from_memory(&bytes).expect("png").into_luma8();
    let values: Vec<bool> = image.pixels().map(|pixel| pixel.0[0] > 127).collect();
    BitMask::from_bools(image.width(), image.height(), &values).expect("mask")
}

pub(crate) fn distance(a: [f32; 3], b: glam::Vec3) -> f32 {
    (glam::Vec3::from_array(a) - b).length()
}

/// Uploads `files` as a zip, checks the scene is dynamic with `time_count` times; its id.
pub(crate) async fn upload_dynamic(
    client: &TestService,
    files: &[(String, Vec<u8>)],
    time_count: usize,
) -> String {
    let (status, scene) = client
        .upload(archives::zip_of(files), "application/zip")
        .await;
    assert_eq!(status, 201, "{scene}");
    assert_eq!(scene["dynamic"], true, "{scene}");
    assert_eq!(scene["time_count"], time_count, "{scene}");
    scene["id"].as_str().expect("id").to_string()
}

/// Uploads the moving spheres of [`spec`] (D-NeRF layout, one time per frame); the scene's id.
pub(crate) async fn upload_moving_spheres(client: &TestService) -> String {
    let files = archives::dataset_files(|dir| {
        segsplat_scene::synthetic_dynamic::write_dynamic_blender(dir, &spec())
    });
    upload_dynamic(client, &files, FRAMES).await
}

/// A trained camera (an entry of `cameras.json`) as a gRPC pose view.
pub(crate) fn pose_view_of(camera: &serde_json::Value) -> proto::PoseView {
    let rows: Vec<f64> = camera["camera_to_world"]
        .as_array()
        .expect("rows")
        .iter()
        .flat_map(|row| {
            row.as_array()
                .expect("row")
                .iter()
                .map(|v| v.as_f64().expect("f64"))
        })
        .collect();
    proto::PoseView {
        pose: Some(proto::Pose {
            camera_to_world: rows,
        }),
        intrinsics: Some(proto::Intrinsics {
            fx: camera["fx"].as_f64().expect("fx"),
            fy: camera["fy"].as_f64().expect("fy"),
            cx: camera["cx"].as_f64().expect("cx"),
            cy: camera["cy"].as_f64().expect("cy"),
            width: camera["width"].as_u64().expect("width") as u32,
            height: camera["height"].as_u64().expect("height") as u32,
        }),
    }
}

pub(crate) fn png_bools(bytes: &[u8]) -> Vec<bool> {
    let image = image::load_from_memory(bytes).expect("png").into_luma8();
    image.pixels().map(|p| p.0[0] > 127).collect()
}

/// A listed object's centroid (REST `objects` or a query match).
pub(crate) fn centroid_of(object: &serde_json::Value) -> [f32; 3] {
    serde_json::from_value(object["centroid"].clone()).expect("centroid")
}

/// GET answered 200 (else a panic showing the body): its bytes.
pub(crate) async fn get_ok(client: &TestService, path: &str) -> Vec<u8> {
    let (status, bytes) = client.get_bytes(path).await;
    assert_eq!(status, 200, "{path}: {}", String::from_utf8_lossy(&bytes));
    bytes
}

/// A PLY's header: everything before `end_header` (format, vertex count, properties).
pub(crate) fn ply_header(bytes: &[u8]) -> &[u8] {
    let end = bytes
        .windows(b"end_header".len())
        .position(|window| window == b"end_header")
        .expect("a PLY header");
    &bytes[..end]
}

/// Opacity-weighted mean position of the Gaussians `labels` gives `object_id` at `level`, over
/// those more than 5% opaque: how the service summarises an object's centroid.
pub(crate) fn labelled_centroid(
    model: &GaussianModel,
    labels: &[[u32; 3]],
    level: Level,
    object_id: u32,
) -> glam::Vec3 {
    let mut sum = glam::DVec3::ZERO;
    let mut weight_sum = 0.0;
    for (index, ids) in labels.iter().enumerate() {
        let opacity = 1.0 / (1.0 + (-f64::from(model.opacity_logits[index])).exp());
        if ids[level.index()] == object_id && opacity > 0.05 {
            weight_sum += opacity;
            sum += opacity * glam::DVec3::from_array(model.means[index].map(f64::from));
        }
    }
    assert!(weight_sum > 0.0, "no opaque Gaussian of object {object_id}");
    (sum / weight_sum).as_vec3()
}
