//! Turning a camera video into numbered frame images with the `ffmpeg` program.
//!
//! ffmpeg rather than a decoder crate: multi-view video datasets ship H.264 or HEVC in MP4 with
//! High-profile features (CABAC, B-frames) that the pure-crates.io decoders do not cover, and one
//! well-known binary decodes all of them. Its absence is a clear server-side error, not a panic.
//! Frames are written as high-quality JPEG (`-q:v 2`): they come from lossy video already, and
//! PNG would make a Neu3D scene (6000 frames) several times larger in the blob store.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::process::Command;

use super::{SceneError, VideoFrameOptions};

/// Extension of the frames [`extract_video_frames`] writes.
pub const EXTRACTED_EXTENSION: &str = "jpg";

/// How many characters of ffmpeg's error output an error message keeps (its last lines).
const STDERR_TAIL_CHARS: usize = 600;

/// Decodes `video` (relative to `root`) into `output_dir` (relative to `root`) as
/// `00000.jpg, 00001.jpg, ...`, resized to `width` x `height` (or kept at the video's size when
/// it is smaller), keeping every
/// `frame_step`-th frame up to `max_frames`. Frames go to a hidden sibling folder first and are
/// renamed into place at the end, so an interrupted run never looks like a finished one.
/// Returns how many frames were written.
pub fn extract_video_frames(
    root: &Path,
    video: &Path,
    output_dir: &Path,
    (width, height): (u32, u32),
    options: &VideoFrameOptions,
) -> Result<usize, SceneError> {
    let video_file = video.display().to_string();
    let output_file = output_dir.display().to_string();
    let io_error = |file: &str| {
        let file = file.to_string();
        move |source: io::Error| SceneError::Io { file, source }
    };
    let video_path = std::path::absolute(root.join(video)).map_err(io_error(&video_file))?;
    let output_path = root.join(output_dir);
    let parent = output_path
        .parent()
        .map_or_else(|| root.to_path_buf(), Path::to_path_buf);
    fs::create_dir_all(&parent).map_err(io_error(&output_file))?;
    let staging = tempfile::Builder::new()
        .prefix(".extract-")
        .tempdir_in(&parent)
        .map_err(io_error(&output_file))?;
    let pattern = std::path::absolute(staging.path().join(format!("%05d.{EXTRACTED_EXTENSION}")))
        .map_err(io_error(&output_file))?;

    let output = Command::new(&options.ffmpeg)
        .args(ffmpeg_arguments(
            &video_path,
            &pattern,
            (width, height),
            options,
        ))
        .output()
        .map_err(|source| match source.kind() {
            io::ErrorKind::NotFound => SceneError::VideoDecoderMissing {
                program: options.ffmpeg.display().to_string(),
            },
            _ => SceneError::Io {
                file: options.ffmpeg.display().to_string(),
                source,
            },
        })?;
    if !output.status.success() {
        return Err(SceneError::UndecodableVideo {
            file: video_file,
            message: format!(
                "ffmpeg failed ({}): {}",
                output.status,
                stderr_tail(&output.stderr)
            ),
        });
    }
    let written = fs::read_dir(staging.path())
        .map_err(io_error(&output_file))?
        .filter_map(|entry| entry.ok())
        .count();
    if written == 0 {
        return Err(SceneError::UndecodableVideo {
            file: video_file,
            message: "no frames could be decoded".to_string(),
        });
    }
    // An empty folder left where the frames go (e.g. unpacked from the archive) is replaced.
    if output_path.is_dir() {
        fs::remove_dir(&output_path).map_err(io_error(&output_file))?;
    }
    let staged: PathBuf = staging.keep();
    fs::rename(&staged, &output_path).map_err(|source| {
        let _ = fs::remove_dir_all(&staged);
        SceneError::Io {
            file: output_file.clone(),
            source,
        }
    })?;
    tracing::info!(video = %video_file, frames = written, width, height, "extracted video frames");
    Ok(written)
}

fn ffmpeg_arguments(
    video_path: &Path,
    pattern: &Path,
    (width, height): (u32, u32),
    options: &VideoFrameOptions,
) -> Vec<std::ffi::OsString> {
    let mut filters = Vec::new();
    if options.frame_step > 1 {
        // `n` is the decoded frame number; the image2 muxer keeps the survivors without
        // duplicating frames to fill the gaps.
        filters.push(format!("select=not(mod(n\\,{}))", options.frame_step));
    }
    // Never upscale: a video smaller than the target keeps its size (the loader scales the
    // camera to the frames it finds).
    filters.push(format!(
        "scale=w=min(iw\\,{width}):h=min(ih\\,{height}):flags=area"
    ));
    let mut arguments: Vec<std::ffi::OsString> =
        ["-nostdin", "-hide_banner", "-loglevel", "error", "-y", "-i"]
            .into_iter()
            .map(Into::into)
            .collect();
    arguments.push(video_path.into());
    arguments.extend(["-vf".into(), filters.join(",").into()]);
    if let Some(max_frames) = options.max_frames {
        arguments.extend(["-frames:v".into(), max_frames.to_string().into()]);
    }
    arguments.extend(
        ["-start_number", "0", "-q:v", "2"]
            .into_iter()
            .map(Into::into),
    );
    arguments.push(pattern.into());
    arguments
}

fn stderr_tail(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let text = text.trim();
    let start = text
        .char_indices()
        .rev()
        .nth(STDERR_TAIL_CHARS)
        .map_or(0, |(index, _)| index);
    text[start..].to_string()
}
