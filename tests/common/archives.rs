//! Synthetic datasets packed as the archives clients upload.

use std::io::Write;
use std::path::Path;

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{self, SyntheticSpec};
use zip::write::SimpleFileOptions;

/// Small enough to keep uploads and validation fast.
pub fn small_spec() -> SyntheticSpec {
    SyntheticSpec {
        frame_count: 4,
        width: 16,
        height: 12,
        ..SyntheticSpec::default()
    }
}

/// A scene the stand-in CLIP can name: 9 views of 96 x 72 with masks at every level, as a
/// COLMAP zip. 96 x 72 rather than 48 x 36: the stand-in CLIP quantises a crop's mean colour to
/// the nearest prototype, and on tiny crops the shaded sphere plus the resize's dark edge ring
/// reads as "brown" (measured: "red" scored 0.08 against the red sphere at 48 x 36).
pub fn queryable_scene_zip() -> Vec<u8> {
    let spec = SyntheticSpec {
        frame_count: 9,
        width: 96,
        height: 72,
        with_masks: Some(segsplat_scene::Level::ALL.to_vec()),
        ..SyntheticSpec::default()
    };
    zip_of(&colmap_files(spec, ColmapEncoding::Text))
}

/// Every file under `dir` as (relative `/` path, bytes), sorted.
pub fn read_tree(dir: &Path) -> Vec<(String, Vec<u8>)> {
    super::files_under(dir)
        .into_iter()
        .map(|relative| {
            let name = relative
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join("/");
            let bytes = std::fs::read(dir.join(&relative)).unwrap();
            (name, bytes)
        })
        .collect()
}

pub fn zip_of(files: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut writer = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, bytes) in files {
        writer
            .start_file(name.as_str(), SimpleFileOptions::default())
            .unwrap();
        writer.write_all(bytes).unwrap();
    }
    writer.finish().unwrap().into_inner()
}

pub fn tar_of(files: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut builder = tar::Builder::new(Vec::new());
    for (name, bytes) in files {
        let mut header = tar::Header::new_gnu();
        header.set_size(bytes.len() as u64);
        header.set_mode(0o644);
        builder
            .append_data(&mut header, name, bytes.as_slice())
            .unwrap();
    }
    builder.into_inner().unwrap()
}

pub fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}

/// Writes a dataset with `write` into a temporary folder and returns its files.
pub fn dataset_files(write: impl FnOnce(&Path) -> std::io::Result<()>) -> Vec<(String, Vec<u8>)> {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path()).unwrap();
    read_tree(dir.path())
}

pub fn colmap_files(spec: SyntheticSpec, encoding: ColmapEncoding) -> Vec<(String, Vec<u8>)> {
    dataset_files(|dir| synthetic::write_colmap(dir, &spec, encoding))
}

pub fn colmap_zip(spec: SyntheticSpec) -> Vec<u8> {
    zip_of(&colmap_files(spec, ColmapEncoding::Text))
}

/// Files with `prefix/` put in front of every name (a dataset archived as its folder).
pub fn wrapped(prefix: &str, files: Vec<(String, Vec<u8>)>) -> Vec<(String, Vec<u8>)> {
    files
        .into_iter()
        .map(|(name, bytes)| (format!("{prefix}/{name}"), bytes))
        .collect()
}
