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

/// The largest requested time, either side of 0. Times are normalised (0..1 spans the training
/// frames); far outside that the deformation field extrapolates into noise. A bound with few
/// digits also parses exactly, so the server and the document ([`super::schema_names::TimeValue`])
/// agree on which values pass, where `f32::MAX` would be at the mercy of rounding.
pub const TIME_LIMIT: f64 = 1e6;

/// Checks a requested time is a number within [`TIME_LIMIT`] (read as `f64`, so the check is the
/// documented one and not that of a value rounded to `f32`).
pub fn parse_time(time: Option<f64>) -> Result<Option<f32>, ApiError> {
    match time {
        None => Ok(None),
        Some(value) if value.abs() <= TIME_LIMIT => Ok(Some(value as f32)),
        Some(value) => Err(ApiError::bad_request(format!(
            "time: {value} is outside -{TIME_LIMIT}..={TIME_LIMIT}"
        ))),
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
