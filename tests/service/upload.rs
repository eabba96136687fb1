//! Scene upload end to end: every dataset format and archive kind accepted, and what is stored
//! reloads. Malformed and oversized uploads are in [`crate::upload_checks`].

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{self, SyntheticSpec};
use segsplat_scene::synthetic_dynamic_formats;

use crate::common::archives::{
    self, colmap_files, dataset_files, gzip, small_spec, tar_of, wrapped, zip_of,
};
use crate::common::{TestService, entries_in, files_under, test_config};

pub(crate) async fn start(dir: &std::path::Path) -> TestService {
    TestService::start(test_config(dir), vec![]).await
}

/// Nothing from failed uploads: no scene rows, no blobs, no temporary files.
pub(crate) async fn assert_no_trace(service: &TestService, data_dir: &std::path::Path) {
    let (status, body) = service.get_json("/v1/scenes").await;
    assert_eq!(status, 200);
    assert_eq!(body["scenes"].as_array().unwrap().len(), 0, "{body}");
    assert!(
        files_under(&data_dir.join("blobs")).is_empty(),
        "blobs left behind"
    );
    assert!(
        entries_in(&data_dir.join("tmp")).is_empty(),
        "temporary files left behind: {:?}",
        entries_in(&data_dir.join("tmp"))
    );
}

/// The stored files alone load and validate as the same dataset: nothing the loader reads was
/// left out of the blob store.
pub(crate) async fn assert_stored_scene_reloads(
    service: &TestService,
    data_dir: &std::path::Path,
    id: &str,
) {
    let (_, body) = service.get_json(&format!("/v1/scenes/{id}")).await;
    let files = data_dir.join("blobs/scenes").join(id).join("files");
    let scene = segsplat_scene::load_scene(&files, &segsplat_scene::LoadOptions::default())
        .unwrap_or_else(|error| panic!("{body}: stored files do not load: {error}"));
    assert_eq!(
        scene.frames.len() as u64,
        body["frame_count"].as_u64().unwrap(),
        "{body}"
    );
    segsplat_scene::validate_scene(&scene)
        .unwrap_or_else(|error| panic!("{body}: stored files do not validate: {error}"));
}

#[tokio::test]
async fn every_format_and_archive_kind_uploads() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let spec = small_spec();
    let masked = SyntheticSpec {
        with_masks: Some(vec![segsplat_scene::Level::Small]),
        ..small_spec()
    };
    let cases: Vec<(&str, Vec<u8>, &str, &str, u32)> = vec![
        (
            "colmap text zip",
            zip_of(&colmap_files(spec.clone(), ColmapEncoding::Text)),
            "application/zip",
            "colmap",
            4,
        ),
        (
            "colmap binary tar.gz, wrapped in a folder",
            gzip(&tar_of(&wrapped(
                "garden",
                colmap_files(masked, ColmapEncoding::Binary),
            ))),
            "application/gzip",
            "colmap",
            4,
        ),
        (
            "nerfstudio tar",
            tar_of(&dataset_files(|d| synthetic::write_nerfstudio(d, &spec))),
            "application/x-tar",
            "nerfstudio",
            4,
        ),
        (
            "blender zip",
            zip_of(&dataset_files(|d| {
                synthetic::write_blender(
                    d,
                    &SyntheticSpec {
                        frame_count: 4,
                        ..spec.clone()
                    },
                )
            })),
            "application/octet-stream",
            "blender",
            4,
        ),
    ];
    let mut ids = Vec::new();
    for (label, bytes, content_type, format, frames) in cases {
        let (status, body) = service.upload(bytes, content_type).await;
        assert_eq!(status, 201, "{label}: {body}");
        assert_eq!(body["format"], format, "{label}");
        assert_eq!(body["frame_count"], frames, "{label}");
        assert_eq!(
            body["resolutions"],
            serde_json::json!([[16, 12]]),
            "{label}"
        );
        ids.push(body["id"].as_str().unwrap().to_string());
    }
    // Sparse points come with COLMAP; masks were given at one level for the wrapped upload.
    let (_, colmap) = service.get_json(&format!("/v1/scenes/{}", ids[0])).await;
    assert!(
        colmap["sparse_point_count"].as_u64().unwrap() > 0,
        "{colmap}"
    );
    let (_, masked) = service.get_json(&format!("/v1/scenes/{}", ids[1])).await;
    assert_eq!(
        masked["mask_levels"],
        serde_json::json!(["small"]),
        "{masked}"
    );
    for id in &ids {
        assert_stored_scene_reloads(&service, dir.path(), id).await;
    }
    // The files are stored under the scene (the wrapping folder removed).
    let stored = files_under(&dir.path().join("blobs/scenes").join(&ids[1]).join("files"));
    assert!(
        stored.iter().any(|p| p.starts_with("sparse/0")),
        "{stored:?}"
    );
    assert!(stored.iter().any(|p| p.starts_with("images")), "{stored:?}");

    let (status, list) = service.get_json("/v1/scenes").await;
    assert_eq!(status, 200);
    assert_eq!(list["scenes"].as_array().unwrap().len(), 4);

    // Delete removes the row and the files.
    let response = service
        .client
        .delete(service.url(&format!("/v1/scenes/{}", ids[1])))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 204);
    let (status, body) = service.get_json(&format!("/v1/scenes/{}", ids[1])).await;
    assert_eq!(status, 404);
    assert_eq!(body["error"]["code"], "not_found");
    assert!(!dir.path().join("blobs/scenes").join(&ids[1]).exists());
    service.shutdown().await;
}

#[tokio::test]
async fn dynamic_formats_upload_and_say_they_are_dynamic() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let spec = small_spec();
    let nerfies = dataset_files(|d| synthetic_dynamic_formats::write_nerfies(d, &spec));
    let cases: Vec<(&str, Vec<u8>, &str, u32, u32)> = vec![
        ("nerfies zip", zip_of(&nerfies), "nerfies", 4, 4),
        (
            "neu3d frames tar, wrapped in a folder",
            tar_of(&wrapped(
                "coffee",
                dataset_files(|d| synthetic_dynamic_formats::write_neu3d(d, &spec, 3)),
            )),
            "neu3d",
            12,
            3,
        ),
        (
            "neu3d videos zip",
            zip_of(&dataset_files(|d| {
                synthetic_dynamic_formats::write_neu3d_videos(d, &spec, 2)
            })),
            "neu3d",
            8,
            2,
        ),
        (
            "d-nerf zip",
            zip_of(&dataset_files(|d| {
                synthetic::write_blender(
                    d,
                    &SyntheticSpec {
                        with_time: true,
                        ..spec.clone()
                    },
                )
            })),
            "blender",
            4,
            4,
        ),
    ];
    let mut ids = Vec::new();
    for (label, bytes, format, frames, times) in cases {
        let (status, body) = service.upload(bytes, "application/octet-stream").await;
        assert_eq!(status, 201, "{label}: {body}");
        assert_eq!(body["format"], format, "{label}");
        assert_eq!(body["frame_count"], frames, "{label}");
        assert_eq!(body["dynamic"], true, "{label}");
        assert_eq!(body["time_count"], times, "{label}");
        assert_eq!(
            body["resolutions"],
            serde_json::json!([[16, 12]]),
            "{label}"
        );
        ids.push(body["id"].as_str().unwrap().to_string());
    }
    for id in &ids {
        assert_stored_scene_reloads(&service, dir.path(), id).await;
    }
    // Frames decoded from the uploaded videos are stored with the scene.
    let stored = files_under(&dir.path().join("blobs/scenes").join(&ids[2]).join("files"));
    assert!(
        stored.iter().any(|p| p.starts_with("cam01/images")),
        "{stored:?}"
    );
    // A static scene says it is not dynamic, also when read back.
    let (status, body) = service
        .upload(archives::colmap_zip(spec.clone()), "application/zip")
        .await;
    assert_eq!(status, 201, "{body}");
    let (_, stored_static) = service
        .get_json(&format!("/v1/scenes/{}", body["id"].as_str().unwrap()))
        .await;
    assert_eq!(stored_static["dynamic"], false, "{stored_static}");
    assert_eq!(stored_static["time_count"], 0, "{stored_static}");

    // A broken Nerfies capture is a 422 naming the missing camera file.
    let broken: Vec<_> = nerfies
        .into_iter()
        .filter(|(name, _)| name != "camera/000001.json")
        .collect();
    let (status, body) = service.upload(zip_of(&broken), "application/zip").await;
    assert_eq!(status, 422, "{body}");
    let message = body["error"]["message"].as_str().unwrap();
    assert!(message.contains("camera/000001.json"), "{message}");
    service.shutdown().await;
}

#[tokio::test]
async fn multipart_upload_is_accepted_and_named_after_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let part = reqwest::multipart::Part::bytes(archives::colmap_zip(small_spec()))
        .file_name("kitchen.zip")
        .mime_str("application/zip")
        .unwrap();
    let form = reqwest::multipart::Form::new().part("file", part);
    let response = service
        .client
        .post(service.url("/v1/scenes"))
        .multipart(form)
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 201);
    let body: serde_json::Value = response.json().await.unwrap();
    assert_eq!(body["name"], "kitchen");
    assert_eq!(body["format"], "colmap");
    service.shutdown().await;
}
