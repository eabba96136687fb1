//! The bodies of the `fuzz/` targets: each takes the bytes a client could send and runs them
//! through one parser the way an upload does, ignoring the result (errors are fine; panics,
//! hangs and unbounded allocations are not). They live in the library, not in `fuzz/`, so the
//! stable test `tests/fuzz_corpus.rs` replays the committed corpus through the very same code
//! on machines without a nightly toolchain.
//!
//! Most parsers read files under a dataset folder, so each call writes its input into a fresh
//! temporary folder first (point `TMPDIR` at a RAM disk when fuzzing for speed).

use std::path::Path;

use super::archive::UnpackLimits;
use super::types::LoadOptions;

/// One target: parse these client bytes, ignoring the outcome.
pub type Target = fn(&[u8]);

/// Every target by name, for the corpus replay test (`fuzz/fuzz_targets/` has one file each).
pub const TARGETS: [(&str, Target); 9] = [
    ("colmap_binary", colmap_binary),
    ("colmap_text", colmap_text),
    ("ply", ply),
    ("transforms_json", transforms_json),
    ("nerfies_json", nerfies_json),
    ("npy", npy),
    ("mask_png", mask_png),
    ("frame_image", frame_image),
    ("archive", archive),
];

/// Splits `data` into `count` parts: each part but the last is prefixed by its length as a
/// little-endian u16 (clamped to what is left), so the fuzzer can grow and shrink each file.
pub fn split_parts(data: &[u8], count: usize) -> Vec<&[u8]> {
    let mut parts = Vec::with_capacity(count);
    let mut rest = data;
    for _ in 1..count {
        let (length, tail) = match rest {
            [low, high, tail @ ..] => (usize::from(u16::from_le_bytes([*low, *high])), tail),
            _ => (0, &[][..]),
        };
        let length = length.min(tail.len());
        parts.push(&tail[..length]);
        rest = &tail[length..];
    }
    parts.push(rest);
    parts
}

/// Joins files into one input that [`split_parts`] takes apart again (for writing seeds).
pub fn join_parts(parts: &[&[u8]]) -> Vec<u8> {
    let mut joined = Vec::new();
    let Some((last, leading)) = parts.split_last() else {
        return joined;
    };
    for part in leading {
        let length = u16::try_from(part.len()).unwrap_or(u16::MAX);
        joined.extend(length.to_le_bytes());
        joined.extend(&part[..usize::from(length)]);
    }
    joined.extend(*last);
    joined
}

/// A temporary dataset folder holding `files` (relative path, bytes); `None` when the
/// machine cannot write one (not the parser's fault, so the input is skipped).
fn dataset(files: &[(&str, &[u8])]) -> Option<tempfile::TempDir> {
    let dir = tempfile::tempdir().ok()?;
    for (name, bytes) in files {
        let path = dir.path().join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).ok()?;
        }
        std::fs::write(path, bytes).ok()?;
    }
    Some(dir)
}

/// A COLMAP model of `cameras`, `images` and `points3D` files with `extension` (see
/// [`split_parts`]), loaded as an upload is.
fn load_colmap_model(data: &[u8], extension: &str) {
    let parts = split_parts(data, 3);
    let names =
        ["cameras", "images", "points3D"].map(|name| format!("sparse/0/{name}.{extension}"));
    let files: Vec<(&str, &[u8])> = names.iter().map(String::as_str).zip(parts).collect();
    let Some(dir) = dataset(&files) else { return };
    if let Some(location) = super::colmap::find_model(dir.path()) {
        let _ = super::colmap::load_colmap(dir.path(), &location, &LoadOptions::default());
    }
}

/// `cameras.bin`, `images.bin`, `points3D.bin`.
pub fn colmap_binary(data: &[u8]) {
    load_colmap_model(data, "bin");
}

/// `cameras.txt`, `images.txt`, `points3D.txt`.
pub fn colmap_text(data: &[u8]) {
    load_colmap_model(data, "txt");
}

/// One uploaded sparse point cloud PLY (nerfstudio `ply_file_path`, Blender `points3d.ply`).
/// Trained-scene PLYs (`splat::ply`) are written by the service itself, not sent by clients.
pub fn ply(data: &[u8]) {
    if let Some(dir) = dataset(&[("points.ply", data)]) {
        let _ = super::point_ply::read_point_ply(dir.path(), Path::new("points.ply"));
    }
}

/// One `transforms.json`, read as nerfstudio and as Blender NeRF / D-NeRF (train split).
pub fn transforms_json(data: &[u8]) {
    let Some(dir) = dataset(&[
        (super::nerfstudio::TRANSFORMS_FILE, data),
        (super::blender::TRAIN_TRANSFORMS_FILE, data),
    ]) else {
        return;
    };
    let options = LoadOptions::default();
    let _ = super::nerfstudio::load_nerfstudio(dir.path(), &options);
    let _ = super::blender::load_blender(dir.path(), &options);
}

/// Nerfies / HyperNeRF: `dataset.json`, `metadata.json`, `scene.json` and the camera file of
/// the first frame id the fuzzer is likely to write (`camera/a.json`), see [`split_parts`].
pub fn nerfies_json(data: &[u8]) {
    let parts = split_parts(data, 4);
    let Some(dir) = dataset(&[
        ("dataset.json", parts[0]),
        ("metadata.json", parts[1]),
        ("scene.json", parts[2]),
        ("camera/a.json", parts[3]),
        ("rgb/1x/.keep", b""),
    ]) else {
        return;
    };
    let _ = super::nerfies::load_nerfies(dir.path(), &LoadOptions::default());
}

/// One `.npy` file read as the (N, 3) points of Nerfies and the (N, 17) poses of Neu3D.
pub fn npy(data: &[u8]) {
    let Some(dir) = dataset(&[("array.npy", data)]) else {
        return;
    };
    for columns in [3, 17] {
        let _ = super::npy::read_float_matrix(dir.path(), "array.npy", columns);
    }
}

/// One user instance-mask image (PNG, or whatever the bytes sniff as).
pub fn mask_png(data: &[u8]) {
    let Some(dir) = dataset(&[("mask.png", data)]) else {
        return;
    };
    let _ = super::masks::decode_mask(dir.path(), Path::new("mask.png"));
}

/// One frame image as an upload validates it: its header size within the default pixel bound
/// (the service checks `limits.max_image_pixels` first), then decoded, JPEGs at 1/8 scale with
/// `jpeg-decoder` and everything else (or what it refuses) in full with the `image` crate.
pub fn frame_image(data: &[u8]) {
    let Some(dir) = dataset(&[("frame.jpg", data)]) else {
        return;
    };
    let path = Path::new("frame.jpg");
    let Ok((width, height)) = super::images::image_size(dir.path(), path) else {
        return;
    };
    if u64::from(width) * u64::from(height) > super::PixelLimits::default().max_image_pixels {
        return;
    }
    let _ = super::images::decoded_size(dir.path(), path);
}

/// One upload archive (zip, tar or tar.gz, sniffed), unpacked under small limits.
pub fn archive(data: &[u8]) {
    let Some(dir) = dataset(&[("upload", data)]) else {
        return;
    };
    let dest = dir.path().join("unpacked");
    if std::fs::create_dir(&dest).is_err() {
        return;
    }
    let limits = UnpackLimits {
        max_unpacked_bytes: 16 << 20,
        max_files: 1000,
    };
    let _ = super::archive::unpack_archive(&dir.path().join("upload"), &dest, &limits);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_round_trip() {
        let joined = join_parts(&[b"ab", b"", b"cdef"]);
        assert_eq!(split_parts(&joined, 3), vec![&b"ab"[..], b"", b"cdef"]);
        // Short or empty input still gives every part.
        assert_eq!(split_parts(&[5], 3).len(), 3);
    }
}
