//! Scene upload end to end: every dataset format and archive kind accepted, every malformed
//! upload rejected with the right status and without leaving anything behind.

mod common;

use common::archives::{
    self, colmap_files, dataset_files, gzip, small_spec, tar_of, wrapped, zip_of,
};
use common::{TestService, entries_in, files_under, test_config};
use segsplat::scene::colmap::ColmapEncoding;
use segsplat::scene::synthetic::{self, SyntheticSpec};
use segsplat::scene::synthetic_dynamic_formats;

async fn start(dir: &std::path::Path) -> TestService {
    TestService::start(test_config(dir), vec![]).await
}

/// Nothing from failed uploads: no scene rows, no blobs, no temporary files.
async fn assert_no_trace(service: &TestService, data_dir: &std::path::Path) {
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

#[tokio::test]
async fn every_format_and_archive_kind_uploads() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let spec = small_spec();
    let masked = SyntheticSpec {
        with_masks: Some(vec![segsplat::scene::Level::Small]),
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

/// A valid COLMAP dataset's files with one change applied.
fn colmap_with(change: impl FnOnce(&mut Vec<(String, Vec<u8>)>)) -> Vec<(String, Vec<u8>)> {
    let mut files = colmap_files(small_spec(), ColmapEncoding::Text);
    change(&mut files);
    files
}

fn tar_with_symlink() -> Vec<u8> {
    let mut builder = tar::Builder::new(Vec::new());
    for (name, bytes) in colmap_files(small_spec(), ColmapEncoding::Text) {
        let mut header = tar::Header::new_gnu();
        header.set_size(bytes.len() as u64);
        header.set_mode(0o644);
        builder
            .append_data(&mut header, name, bytes.as_slice())
            .unwrap();
    }
    let mut header = tar::Header::new_gnu();
    header.set_entry_type(tar::EntryType::Symlink);
    header.set_size(0);
    header.set_mode(0o777);
    builder
        .append_link(&mut header, "images/evil.png", "/etc/passwd")
        .unwrap();
    builder.into_inner().unwrap()
}

fn zip_slip() -> Vec<u8> {
    let mut writer = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, bytes) in colmap_files(small_spec(), ColmapEncoding::Text) {
        writer
            .start_file(name, zip::write::SimpleFileOptions::default())
            .unwrap();
        std::io::Write::write_all(&mut writer, &bytes).unwrap();
    }
    writer
        .start_file(
            "../../escaped.txt",
            zip::write::SimpleFileOptions::default(),
        )
        .unwrap();
    std::io::Write::write_all(&mut writer, b"outside").unwrap();
    writer.finish().unwrap().into_inner()
}

#[tokio::test]
async fn malformed_uploads_are_rejected_without_a_trace() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let valid_tar = tar_of(&colmap_files(small_spec(), ColmapEncoding::Text));
    let truncated = gzip(&valid_tar)[..valid_tar.len() / 8].to_vec();
    let missing_image =
        colmap_with(|files| files.retain(|(name, _)| name != "images/frame_0001.png"));
    let undecodable = colmap_with(|files| {
        for (name, bytes) in files.iter_mut() {
            if name == "images/frame_0002.png" {
                *bytes = b"\x89PNG\r\n\x1a\nnot really a png".to_vec();
            }
        }
    });
    let cases: Vec<(&str, Vec<u8>, &str, u16, &str)> = vec![
        (
            "zip-slip entry",
            zip_slip(),
            "application/zip",
            400,
            "escaped.txt",
        ),
        (
            "symlink entry",
            tar_with_symlink(),
            "application/x-tar",
            400,
            "evil.png",
        ),
        ("truncated tar.gz", truncated, "application/gzip", 400, ""),
        (
            "not an archive",
            b"hello, this is plain text".to_vec(),
            "application/octet-stream",
            415,
            "",
        ),
        (
            "no dataset inside",
            zip_of(&[("notes.txt".to_string(), b"hi".to_vec())]),
            "application/zip",
            415,
            "no dataset found",
        ),
        (
            "missing image",
            zip_of(&missing_image),
            "application/zip",
            422,
            "frame_0001.png",
        ),
        (
            "undecodable image",
            zip_of(&undecodable),
            "application/zip",
            422,
            "frame_0002.png",
        ),
        (
            "wrong content type",
            zip_of(&colmap_files(small_spec(), ColmapEncoding::Text)),
            "text/plain",
            415,
            "Content-Type",
        ),
    ];
    for (label, bytes, content_type, expected_status, message_part) in cases {
        let (status, body) = service.upload(bytes, content_type).await;
        assert_eq!(status, expected_status, "{label}: {body}");
        let message = body["error"]["message"].as_str().unwrap_or_default();
        assert!(message.contains(message_part), "{label}: {message}");
        assert!(body["error"]["code"].is_string(), "{label}: {body}");
        assert_no_trace(&service, dir.path()).await;
    }
    assert!(!dir.path().join("escaped.txt").exists());
    assert!(!dir.path().parent().unwrap().join("escaped.txt").exists());
    service.shutdown().await;
}

#[tokio::test]
async fn uploads_over_the_size_limits_get_413() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    let archive = archives::colmap_zip(small_spec());
    config.limits.max_upload_bytes = (archive.len() / 2) as u64;
    let service = TestService::start(config, vec![]).await;
    let (status, body) = service.upload(archive.clone(), "application/zip").await;
    assert_eq!(status, 413, "{body}");
    assert!(
        body["error"]["message"]
            .as_str()
            .unwrap()
            .contains("max_upload_bytes"),
        "{body}"
    );
    // Streamed without a Content-Length: the limit is enforced while receiving.
    let chunks: Vec<Result<Vec<u8>, std::io::Error>> = archive
        .chunks(1024)
        .map(|chunk| Ok(chunk.to_vec()))
        .collect();
    let response = service
        .client
        .post(service.url("/v1/scenes"))
        .header("content-type", "application/zip")
        .body(reqwest::Body::wrap_stream(futures::stream::iter(chunks)))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 413);
    assert_no_trace(&service, dir.path()).await;
    service.shutdown().await;

    // Unpacked size (zip bomb guard).
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.limits.max_unpacked_bytes = 1000;
    let service = TestService::start(config, vec![]).await;
    let (status, body) = service.upload(archive, "application/zip").await;
    assert_eq!(status, 413, "{body}");
    assert_no_trace(&service, dir.path()).await;
    service.shutdown().await;
}
