//! Decoding frame images for validation and for the engine.
//!
//! Pixel values stay in the images' sRGB encoding as 0..1 floats (what 3DGS trains on); RGBA is
//! composited on the scene background in that same encoding.

use std::io;
use std::path::Path;

use image::imageops::FilterType;
use image::{DynamicImage, ImageReader, Rgb32FImage};

use super::distortion::{Lens, undistort_rgb};
use super::jpeg_scaled::{ScaledJpeg, decode_scaled};
use super::{Frame, Scene, SceneError};

/// Image size after scaling by `factor`, rounded, at least one pixel per side.
pub fn scaled_size(width: u32, height: u32, factor: f64) -> (u32, u32) {
    let scale = |side: u32| ((f64::from(side) * factor).round() as u32).max(1);
    (scale(width), scale(height))
}

/// The factor (at most 1) that brings the longest side down to `max_side`.
pub fn scale_for_max_side(width: u32, height: u32, max_side: u32) -> f64 {
    let longest = width.max(height);
    if longest <= max_side || longest == 0 {
        1.0
    } else {
        f64::from(max_side.max(1)) / f64::from(longest)
    }
}

/// Decodes the image at `relative_path` under `root`; errors name that relative path.
pub(crate) fn decode_image(root: &Path, relative_path: &Path) -> Result<DynamicImage, SceneError> {
    let file = relative_path.display().to_string();
    let reader =
        ImageReader::open(root.join(relative_path)).map_err(|source| match source.kind() {
            io::ErrorKind::NotFound => SceneError::MissingImage { file: file.clone() },
            _ => SceneError::Io {
                file: file.clone(),
                source,
            },
        })?;
    let reader = reader
        .with_guessed_format()
        .map_err(|source| SceneError::Io {
            file: file.clone(),
            source,
        })?;
    reader
        .decode()
        .map_err(|error| SceneError::UndecodableImage {
            file,
            message: error.to_string(),
        })
}

/// The size of the image at `relative_path` under `root`, from its header only (loaders that
/// must know image sizes before validation decodes anything); errors name that relative path.
pub(crate) fn image_size(root: &Path, relative_path: &Path) -> Result<(u32, u32), SceneError> {
    let file = relative_path.display().to_string();
    let full_path = root.join(relative_path);
    if !full_path.is_file() {
        return Err(SceneError::MissingImage { file });
    }
    image::image_dimensions(&full_path).map_err(|error| SceneError::UndecodableImage {
        file,
        message: error.to_string(),
    })
}

/// Frame `frame_index` as 0..1 RGB floats, RGBA composited on `scene.background`, undistorted to
/// the pinhole camera with the frame's `fx, fy, cx, cy` when its camera model has distortion
/// (bilinear, at full resolution; see [`crate::distortion`]), then downscaled so the
/// longest side is at most `max_side` (Lanczos3, never upscaled). Scale the frame's
/// intrinsics with [`crate::Intrinsics::scaled`] and the same
/// [`scale_for_max_side`] factor to match.
pub fn load_frame_rgb(
    scene: &Scene,
    frame_index: usize,
    max_side: Option<u32>,
) -> Result<Rgb32FImage, SceneError> {
    let frame = scene
        .frames
        .get(frame_index)
        .ok_or_else(|| SceneError::Inconsistent {
            file: scene.root.display().to_string(),
            message: format!(
                "frame {frame_index} requested but the scene has {} frames",
                scene.frames.len()
            ),
        })?;
    let (width, height) = (frame.intrinsics.width, frame.intrinsics.height);
    let factor = max_side.map_or(1.0, |max_side| scale_for_max_side(width, height, max_side));
    let target = scaled_size(width, height, factor);
    // A pinhole frame used below full size: JPEGs decode at a DCT scale near that size. Lens
    // distortion is undone at full resolution, so distorted frames decode in full.
    let rgb = match decode_reduced(scene, frame, target, factor)? {
        Some(reduced) => reduced,
        None => {
            let decoded = decode_image(&scene.root, &frame.image_path)?;
            let actual = (decoded.width(), decoded.height());
            if actual != (width, height) {
                return Err(size_mismatch(&frame.image_path, actual, (width, height)));
            }
            undistorted(frame, composite_on_background(decoded, scene.background))?
        }
    };
    if (rgb.width(), rgb.height()) == target {
        return Ok(rgb);
    }
    let mut resized = image::imageops::resize(&rgb, target.0, target.1, FilterType::Lanczos3);
    // Lanczos rings slightly past the input range at hard edges.
    for value in resized.iter_mut() {
        *value = value.clamp(0.0, 1.0);
    }
    Ok(resized)
}

/// The frame's image decoded at a reduced size covering `target`, when it is a JPEG of a
/// pinhole camera used below full size; `None` to decode in full.
fn decode_reduced(
    scene: &Scene,
    frame: &Frame,
    target: (u32, u32),
    factor: f64,
) -> Result<Option<Rgb32FImage>, SceneError> {
    if factor >= 1.0 || !frame_lens(frame)?.is_pinhole() || !is_jpeg(&scene.root, &frame.image_path)
    {
        return Ok(None);
    }
    let Some(scaled) = jpeg_at_scale(&scene.root, &frame.image_path, target) else {
        return Ok(None);
    };
    let expected = (frame.intrinsics.width, frame.intrinsics.height);
    if scaled.full_size != expected {
        return Err(size_mismatch(&frame.image_path, scaled.full_size, expected));
    }
    Ok(Some(composite_on_background(
        scaled.image,
        scene.background,
    )))
}

/// The JPEG at `relative_path` decoded at the DCT scale nearest above `target`; `None` when it
/// cannot be (not a JPEG, no smaller scale, a format or error of `jpeg-decoder`): callers then
/// decode in full with the `image` crate, whose verdict and messages are the ones users see.
fn jpeg_at_scale(root: &Path, relative_path: &Path, target: (u32, u32)) -> Option<ScaledJpeg> {
    if !is_jpeg(root, relative_path) {
        return None;
    }
    let reader = std::fs::File::open(root.join(relative_path)).ok()?;
    decode_scaled(reader, target)
        .inspect_err(|message| {
            tracing::debug!(file = %relative_path.display(), %message, "scaled JPEG decode failed")
        })
        .ok()
        .flatten()
}

/// Decodes the image at `relative_path` to prove it decodes, and returns its size: JPEGs at an
/// eighth of their size (every coefficient is still entropy-decoded, so damage shows), other
/// formats in full.
pub(crate) fn decoded_size(root: &Path, relative_path: &Path) -> Result<(u32, u32), SceneError> {
    if let Some(scaled) = jpeg_at_scale(root, relative_path, (1, 1)) {
        return Ok(scaled.full_size);
    }
    let image = decode_image(root, relative_path)?;
    Ok((image.width(), image.height()))
}

/// Whether the file's first bytes are a JPEG's start-of-image marker.
fn is_jpeg(root: &Path, relative_path: &Path) -> bool {
    let mut start = [0u8; 3];
    std::fs::File::open(root.join(relative_path))
        .and_then(|mut file| io::Read::read_exact(&mut file, &mut start))
        .is_ok_and(|()| start == [0xFF, 0xD8, 0xFF])
}

/// The lens of `frame`'s camera; errors name the frame's image.
pub(crate) fn frame_lens(frame: &Frame) -> Result<Lens, SceneError> {
    Lens::from_intrinsics(&frame.intrinsics).map_err(|message| SceneError::Inconsistent {
        file: frame.image_path.display().to_string(),
        message: format!("camera of frame {}: {message}", frame.name),
    })
}

/// Share of remapped pixels taken from outside the distorted image above which a warning says so.
pub(crate) const OUTSIDE_WARNING_FRACTION: f64 = 0.02;

fn undistorted(frame: &Frame, rgb: Rgb32FImage) -> Result<Rgb32FImage, SceneError> {
    let lens = frame_lens(frame)?;
    if lens.is_pinhole() {
        return Ok(rgb);
    }
    let (pinhole, stats) = undistort_rgb(&rgb, &frame.intrinsics, &lens);
    if stats.outside_fraction > OUTSIDE_WARNING_FRACTION {
        tracing::warn!(
            frame = %frame.name,
            model = %frame.intrinsics.model,
            outside_percent = stats.outside_fraction * 100.0,
            "undistorted image has pixels from outside the original, filled from its edge"
        );
    }
    Ok(pinhole)
}

pub(crate) fn size_mismatch(file: &Path, actual: (u32, u32), expected: (u32, u32)) -> SceneError {
    SceneError::Inconsistent {
        file: file.display().to_string(),
        message: format!(
            "image is {}x{} but its camera says {}x{}",
            actual.0, actual.1, expected.0, expected.1
        ),
    }
}

fn composite_on_background(decoded: DynamicImage, background: [f32; 3]) -> Rgb32FImage {
    if !decoded.color().has_alpha() {
        return decoded.into_rgb32f();
    }
    let rgba = decoded.into_rgba32f();
    let mut rgb = Rgb32FImage::new(rgba.width(), rgba.height());
    for (out, pixel) in rgb.pixels_mut().zip(rgba.pixels()) {
        let [red, green, blue, alpha] = pixel.0;
        let alpha = alpha.clamp(0.0, 1.0);
        out.0 = [
            red * alpha + background[0] * (1.0 - alpha),
            green * alpha + background[1] * (1.0 - alpha),
            blue * alpha + background[2] * (1.0 - alpha),
        ];
    }
    rgb
}
