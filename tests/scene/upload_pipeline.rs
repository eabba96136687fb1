//! Archive in, validated scene out: what the upload endpoint does, without HTTP.

use std::fs;
use std::io::Write;
use std::path::Path;

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{self, SyntheticSpec};
use segsplat_scene::{
    Level, LoadOptions, SceneFormat, UnpackLimits, load_scene, unpack_archive, validate_scene,
};
use zip::write::SimpleFileOptions;

/// Zips every file under `source`, prefixed with `prefix` (a wrapping folder, or "").
fn zip_dir(source: &Path, prefix: &str, archive: &Path) {
    let mut writer = zip::ZipWriter::new(fs::File::create(archive).unwrap());
    let mut stack = vec![source.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            let relative = path.strip_prefix(source).unwrap().to_string_lossy();
            writer
                .start_file(format!("{prefix}{relative}"), SimpleFileOptions::default())
                .unwrap();
            writer.write_all(&fs::read(&path).unwrap()).unwrap();
        }
    }
    writer.finish().unwrap();
}

fn tar_gz_dir(source: &Path, archive: &Path) {
    let encoder = flate2::write::GzEncoder::new(
        fs::File::create(archive).unwrap(),
        flate2::Compression::fast(),
    );
    let mut builder = tar::Builder::new(encoder);
    builder.append_dir_all(".", source).unwrap();
    builder.into_inner().unwrap().finish().unwrap();
}

#[test]
fn zipped_wrapped_colmap_scene_with_masks_round_trips() {
    let work = tempfile::tempdir().unwrap();
    let source = work.path().join("source");
    let spec = SyntheticSpec {
        with_masks: Some(vec![Level::Small, Level::Large]),
        ..SyntheticSpec::default()
    };
    synthetic::write_colmap(&source, &spec, ColmapEncoding::Binary).unwrap();
    let archive = work.path().join("upload.zip");
    zip_dir(&source, "garden_capture/", &archive);
    let dest = work.path().join("unpacked");
    fs::create_dir(&dest).unwrap();
    let stats = unpack_archive(&archive, &dest, &UnpackLimits::default()).unwrap();
    // 6 images, 12 masks, 3 model files.
    assert_eq!(stats.files, 21);
    let scene = load_scene(&dest, &LoadOptions::default()).unwrap();
    assert_eq!(scene.root, dest.join("garden_capture"));
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.format, SceneFormat::Colmap);
    assert_eq!(summary.frame_count, 6);
    assert_eq!(summary.mask_levels, vec![Level::Small, Level::Large]);
    assert_eq!(summary.sparse_point_count, 144);
}

#[test]
fn tar_gz_blender_scene_round_trips() {
    let work = tempfile::tempdir().unwrap();
    let source = work.path().join("source");
    fs::create_dir(&source).unwrap();
    synthetic::write_blender(&source, &SyntheticSpec::default()).unwrap();
    let archive = work.path().join("upload.tar.gz");
    tar_gz_dir(&source, &archive);
    let dest = work.path().join("unpacked");
    fs::create_dir(&dest).unwrap();
    unpack_archive(&archive, &dest, &UnpackLimits::default()).unwrap();
    let scene = load_scene(&dest, &LoadOptions::default()).unwrap();
    let summary = validate_scene(&scene).unwrap();
    assert_eq!(summary.format, SceneFormat::Blender);
    assert_eq!(summary.frame_count, 6);
    assert_eq!(summary.resolutions, vec![[32, 24]]);
}
