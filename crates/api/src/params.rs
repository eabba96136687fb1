//! Parsing of the query and body parameters several REST resources share (levels, times, mask
//! formats), each error a 400 naming the field.

use segsplat_scene::Level;
use segsplat_service::serving::MaskFormat;

use super::error::ApiError;

pub fn parse_level(name: &str) -> Result<Level, ApiError> {
    Level::ALL
        .into_iter()
        .find(|level| level.name() == name)
        .ok_or_else(|| {
            ApiError::bad_request(format!(
                "level: unknown value {name:?}; expected small, middle or large"
            ))
        })
}

/// Checks a requested time is a number.
pub fn parse_time(time: Option<f32>) -> Result<Option<f32>, ApiError> {
    match time {
        Some(value) if !value.is_finite() => Err(ApiError::bad_request(format!(
            "time: {value} is not a finite number"
        ))),
        other => Ok(other),
    }
}

pub fn parse_mask_format(name: Option<&str>) -> Result<MaskFormat, ApiError> {
    match name {
        None | Some("coco_rle") | Some("rle") => Ok(MaskFormat::CocoRle),
        Some("png") => Ok(MaskFormat::Png),
        Some(other) => Err(ApiError::bad_request(format!(
            "mask_format: unknown value {other:?}; expected png or coco_rle"
        ))),
    }
}
