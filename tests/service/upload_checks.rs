//! What an upload is checked for: every malformed upload rejected with the right status and
//! without leaving anything behind, size and pixel limits, bad entry names and invalid cameras;
//! a client that disconnects mid-ingest still gets its scene, and files the dataset does not use
//! are reported, not stored.

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{self, SyntheticSpec};

use crate::common::archives::{self, colmap_files, gzip, small_spec, tar_of, zip_of};
use crate::common::{TestService, entries_in, files_under, test_config, zip_bomb};
use crate::upload::{assert_no_trace, assert_stored_scene_reloads, start};

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

    // Unpacked size (zip bomb guard): refused from the zip's directory, naming the setting.
    let dir = tempfile::tempdir().unwrap();
    let mut config = test_config(dir.path());
    config.limits.max_unpacked_bytes = 1000;
    let service = TestService::start(config, vec![]).await;
    let (status, body) = service.upload(archive, "application/zip").await;
    assert_eq!(status, 413, "{body}");
    let message = body["error"]["message"].as_str().unwrap_or_default();
    assert!(
        message.contains("declares") && message.contains("limits.max_unpacked_bytes"),
        "{body}"
    );
    assert_no_trace(&service, dir.path()).await;
    service.shutdown().await;

    // The 9 GiB bomb of issue 39 (zip64 sizes in its directory) against the default 8 GiB.
    let dir = tempfile::tempdir().unwrap();
    let service = TestService::start(test_config(dir.path()), vec![]).await;
    let bomb = zip_bomb::zip64_declaring("bomb.bin", b"zeros", 9 << 30);
    let (status, body) = service.upload(bomb, "application/zip").await;
    assert_eq!(status, 413, "{body}");
    assert_eq!(
        body["error"]["message"],
        "the zip's directory declares 9663676416 bytes unpacked, more than the 8589934592 \
         allowed (limits.max_unpacked_bytes)",
        "{body}"
    );
    assert_no_trace(&service, dir.path()).await;
    service.shutdown().await;
}

/// A client that hangs up while its upload is being ingested: the ingest still ends with a
/// recorded scene (not files in the blob store that no scene points at).
#[tokio::test]
async fn client_disconnect_during_ingest_still_records_the_scene() {
    use tokio::io::AsyncWriteExt;

    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    // Enough files that the ingest is still running when the client hangs up.
    let archive = archives::colmap_zip(SyntheticSpec {
        frame_count: 16,
        width: 64,
        height: 48,
        with_masks: Some(segsplat_scene::Level::ALL.to_vec()),
        ..small_spec()
    });
    let addr = service.service.http_addr().unwrap();
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "POST /v1/scenes HTTP/1.1\r\nhost: {addr}\r\ncontent-type: application/zip\r\n\
         content-length: {}\r\n\r\n",
        archive.len()
    );
    stream.write_all(head.as_bytes()).await.unwrap();
    stream.write_all(&archive).await.unwrap();
    stream.flush().await.unwrap();
    // Hang up as soon as the server starts unpacking (the body is then fully received).
    let started = std::time::Instant::now();
    while !entries_in(&dir.path().join("tmp")).iter().any(|path| {
        path.file_name()
            .is_some_and(|name| name.to_string_lossy().starts_with("unpack-"))
    }) {
        assert!(started.elapsed() < std::time::Duration::from_secs(30));
        tokio::time::sleep(std::time::Duration::from_millis(1)).await;
    }
    drop(stream);

    let started = std::time::Instant::now();
    let scenes = loop {
        let (_, body) = service.get_json("/v1/scenes").await;
        let scenes = body["scenes"].as_array().cloned().unwrap_or_default();
        if !scenes.is_empty() {
            break scenes;
        }
        assert!(
            started.elapsed() < std::time::Duration::from_secs(30),
            "no scene recorded after the client hung up; blobs: {:?}",
            files_under(&dir.path().join("blobs")).len()
        );
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    };
    assert_eq!(scenes.len(), 1);
    let id = scenes[0]["id"].as_str().unwrap();
    let stored = entries_in(&dir.path().join("blobs/scenes"));
    assert_eq!(stored.len(), 1, "{stored:?}");
    assert!(stored[0].ends_with(id), "{stored:?} vs {id}");
    service.shutdown().await;
}

/// `zip_of(files)` with every occurrence of the bytes `from` in entry names (local headers and
/// central directory) replaced by `to` of the same length: zip writers refuse the names these
/// tests need (duplicates, invalid UTF-8).
fn zip_with_patched_names(files: &[(String, Vec<u8>)], from: &[u8], to: &[u8]) -> Vec<u8> {
    assert_eq!(from.len(), to.len());
    let mut bytes = zip_of(files);
    let mut at = 0;
    while let Some(found) = bytes[at..].windows(from.len()).position(|w| w == from) {
        let start = at + found;
        bytes[start..start + from.len()].copy_from_slice(to);
        at = start + from.len();
    }
    bytes
}

#[tokio::test]
async fn archives_with_bad_entry_names_get_400_without_a_trace() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let data_dir = dir.path().to_string_lossy().into_owned();
    let mut files = colmap_files(small_spec(), ColmapEncoding::Text);
    files.push(("notes-A.txt".to_string(), b"first".to_vec()));
    files.push(("notes-B.txt".to_string(), b"second".to_vec()));
    let duplicate = zip_with_patched_names(&files, b"notes-B", b"notes-A");
    let invalid_utf8 = zip_with_patched_names(&files, b"notes-B", b"notes\xff\xfe");
    let mut deep = colmap_files(small_spec(), ColmapEncoding::Text);
    deep.push((format!("{}leaf.txt", "d/".repeat(3000)), b"deep".to_vec()));
    let mut long = colmap_files(small_spec(), ColmapEncoding::Text);
    long.push((format!("{}.txt", "n".repeat(300)), b"long".to_vec()));
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "duplicate names",
            duplicate,
            "notes-A.txt: duplicate entry name",
        ),
        ("invalid UTF-8 name", invalid_utf8, "not valid UTF-8"),
        (
            "3000 nested folders",
            zip_of(&deep),
            "nested 3000 folders deep, at most 32",
        ),
        ("3000 nested folders in a tar", tar_of(&deep), "at most 32"),
        ("a 304-byte name", zip_of(&long), "at most 255"),
    ];
    for (label, bytes, message_part) in cases {
        let (status, body) = service.upload(bytes, "application/octet-stream").await;
        assert_eq!(status, 400, "{label}: {body}");
        let message = body["error"]["message"].as_str().unwrap_or_default();
        assert!(message.contains(message_part), "{label}: {message}");
        assert!(
            !message.contains(&data_dir),
            "{label}: server path in {message}"
        );
        assert!(message.len() < 400, "{label}: {message}");
        assert_no_trace(&service, dir.path()).await;
    }
    service.shutdown().await;
}

/// The synthetic nerfstudio dataset with its `transforms.json` changed by `change`.
fn nerfstudio_with(change: impl Fn(&mut serde_json::Value)) -> Vec<u8> {
    let mut files = archives::dataset_files(|d| synthetic::write_nerfstudio(d, &small_spec()));
    for (name, bytes) in files.iter_mut() {
        if name == "transforms.json" {
            let mut json: serde_json::Value = serde_json::from_slice(bytes).unwrap();
            change(&mut json);
            *bytes = serde_json::to_vec(&json).unwrap();
        }
    }
    zip_of(&files)
}

/// Scales the 3x3 rotation part of the first frame's pose column-wise.
fn scale_first_rotation(json: &mut serde_json::Value, columns: [f64; 3]) {
    let matrix = &mut json["frames"][0]["transform_matrix"];
    for row in 0..3 {
        for (column, factor) in columns.iter().enumerate() {
            let value = matrix[row][column].as_f64().unwrap();
            matrix[row][column] = serde_json::json!(value * factor);
        }
    }
}

#[tokio::test]
async fn invalid_cameras_are_refused_at_upload() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let zero_quaternion = colmap_with(|files| {
        for (name, bytes) in files.iter_mut() {
            if name.ends_with("images.txt") {
                let text = String::from_utf8(bytes.clone()).unwrap();
                let mut done = false;
                let lines: Vec<String> = text
                    .lines()
                    .map(|line| {
                        if done || line.starts_with('#') || line.trim().is_empty() {
                            return line.to_string();
                        }
                        done = true;
                        let mut fields: Vec<&str> = line.split_whitespace().collect();
                        fields[1..5].copy_from_slice(&["0", "0", "0", "0"]);
                        fields.join(" ")
                    })
                    .collect();
                *bytes = (lines.join("\n") + "\n").into_bytes();
            }
        }
    });
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "COLMAP all-zero rotation",
            zip_of(&zero_quaternion),
            "not a finite number",
        ),
        (
            "nerfstudio non-orthonormal rotation",
            nerfstudio_with(|json| scale_first_rotation(json, [2.0, 1.0, 1.0])),
            "not orthonormal",
        ),
        (
            "nerfstudio 1e-12-scaled pose",
            nerfstudio_with(|json| scale_first_rotation(json, [1e-12; 3])),
            "not invertible",
        ),
        (
            "nerfstudio all-zero pose",
            nerfstudio_with(|json| scale_first_rotation(json, [0.0; 3])),
            "not invertible",
        ),
        (
            "nerfstudio mirrored pose",
            nerfstudio_with(|json| scale_first_rotation(json, [-1.0, 1.0, 1.0])),
            "reflection",
        ),
        (
            "nerfstudio zero focal length",
            nerfstudio_with(|json| {
                json["fl_x"] = serde_json::json!(0.0);
                json["frames"][0]["fl_x"] = serde_json::json!(0.0);
            }),
            "focal lengths must be positive",
        ),
    ];
    for (label, bytes, message_part) in cases {
        let (status, body) = service.upload(bytes, "application/zip").await;
        assert_eq!(status, 422, "{label}: {body}");
        let message = body["error"]["message"].as_str().unwrap_or_default();
        assert!(message.contains(message_part), "{label}: {message}");
        assert_no_trace(&service, dir.path()).await;
    }
    service.shutdown().await;
}

#[tokio::test]
async fn images_over_the_pixel_limits_get_413_naming_the_limit() {
    // 2000x2000 of one colour: a few KB of PNG that decodes to 16 MB.
    let mut big_png = Vec::new();
    image::RgbImage::new(2000, 2000)
        .write_to(
            &mut std::io::Cursor::new(&mut big_png),
            image::ImageFormat::Png,
        )
        .unwrap();
    assert!(big_png.len() < 100_000);
    let bomb = colmap_with(|files| {
        for (name, bytes) in files.iter_mut() {
            if name == "images/frame_0001.png" {
                *bytes = big_png.clone();
            }
        }
    });
    // small_spec frames are 16x12 = 192 pixels, 768 in all.
    let cases: Vec<(&str, Vec<u8>, u64, u64, &str)> = vec![
        (
            "a frame over the per-image limit",
            zip_of(&bomb),
            1_000_000,
            u64::MAX,
            "images/frame_0001.png: image is 2000x2000 = 4000000 pixels, over the limit of \
             1000000 pixels per image (limits.max_image_pixels)",
        ),
        (
            "frames over the total",
            archives::colmap_zip(small_spec()),
            1_000,
            500,
            "limits.max_total_pixels",
        ),
    ];
    for (label, archive, per_image, total, message_part) in cases {
        let dir = tempfile::tempdir().unwrap();
        let mut config = test_config(dir.path());
        config.limits.max_image_pixels = per_image;
        config.limits.max_total_pixels = total;
        let service = TestService::start(config, vec![]).await;
        let (status, body) = service.upload(archive, "application/zip").await;
        assert_eq!(status, 413, "{label}: {body}");
        let message = body["error"]["message"].as_str().unwrap_or_default();
        assert!(message.contains(message_part), "{label}: {message}");
        assert_no_trace(&service, dir.path()).await;
        service.shutdown().await;
    }
}

#[tokio::test]
async fn files_the_dataset_does_not_use_are_not_stored_and_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let service = start(dir.path()).await;
    let mut files = colmap_files(small_spec(), ColmapEncoding::Text);
    for index in 0..300 {
        files.push((format!("junk/{index:04}.txt"), b"junk".to_vec()));
        files.push((format!("stray_{index:04}.png"), b"not even a png".to_vec()));
    }
    let (status, body) = service.upload(zip_of(&files), "application/zip").await;
    assert_eq!(status, 201, "{body}");
    assert_eq!(body["ignored_file_count"], 600, "{body}");
    let listed = body["ignored_files"].as_array().unwrap();
    assert_eq!(listed.len(), 20, "{body}");
    assert!(listed.iter().all(|name| {
        let name = name.as_str().unwrap();
        name.starts_with("junk/") || name.starts_with("stray_")
    }));
    let id = body["id"].as_str().unwrap();
    let stored = files_under(&dir.path().join("blobs/scenes").join(id).join("files"));
    assert!(
        stored
            .iter()
            .all(|path| path.starts_with("sparse") || path.starts_with("images")),
        "{stored:?}"
    );
    assert_stored_scene_reloads(&service, dir.path(), id).await;
    // Read back, the scene still says what was left out.
    let (_, read_back) = service.get_json(&format!("/v1/scenes/{id}")).await;
    assert_eq!(read_back["ignored_file_count"], 600, "{read_back}");
    service.shutdown().await;
}
