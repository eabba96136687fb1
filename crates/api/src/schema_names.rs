//! OpenAPI schemas of the names the REST API accepts and answers (levels, granularities, mask
//! formats, job and worker states). Fields and parameters stay `String` (the parsers in
//! `params.rs` and the use cases give the 400s their messages); these types only give them their
//! `enum` in the document, built from the domain's own lists so the two cannot drift apart.
//! They are uninhabited: nothing is ever made of them.

use std::borrow::Cow;

use utoipa::openapi::RefOr;
use utoipa::openapi::schema::{KnownFormat, ObjectBuilder, Schema, SchemaFormat, Type};
use utoipa::{PartialSchema, ToSchema};

use super::params::TIME_LIMIT;
use segsplat_engine::deform::file::DEFORMATION_WEIGHTS_FILE;
use segsplat_method::scene_files::{LABELS_FILE, SCENE_FILE};
use segsplat_scene::Level;
use segsplat_service::serving::MaskFormat;
use segsplat_service::store::jobs::JobState;
use segsplat_service::store::workers::WorkerState;
use segsplat_service::usecases::serving::SPZ_FILE;

fn names<I>(description: &str, names: I) -> RefOr<Schema>
where
    I: IntoIterator,
    I::Item: Into<String>,
{
    let values: Vec<String> = names.into_iter().map(Into::into).collect();
    ObjectBuilder::new()
        .schema_type(Type::String)
        .description(Some(description))
        .enum_values(Some(values))
        .into()
}

/// Declares an uninhabited schema type named `$name` whose schema is `$schema`.
macro_rules! name_schema {
    ($(#[$doc:meta])* $name:ident => $schema:expr) => {
        $(#[$doc])*
        pub enum $name {}

        impl PartialSchema for $name {
            fn schema() -> RefOr<Schema> {
                $schema
            }
        }

        impl ToSchema for $name {
            fn name() -> Cow<'static, str> {
                Cow::Borrowed(stringify!($name))
            }
        }
    };
}

fn level_names() -> impl Iterator<Item = &'static str> {
    Level::ALL.into_iter().map(Level::name)
}

/// The spelling of a mask format in requests and answers (serde's, as the gRPC side uses).
pub fn mask_format_name(format: MaskFormat) -> String {
    serde_json::to_value(format)
        .ok()
        .and_then(|value| value.as_str().map(str::to_string))
        .unwrap_or_default()
}

name_schema!(
    /// A granularity level.
    LevelName => names("a granularity level", level_names())
);

name_schema!(
    /// A query's granularity: `auto` or a level.
    GranularityName => names(
        "auto (the better of the best middle and best large object) or one level",
        std::iter::once("auto").chain(level_names()),
    )
);

name_schema!(
    /// A mask encoding.
    MaskFormatName => names(
        "a mask encoding",
        [MaskFormat::CocoRle, MaskFormat::Png].map(mask_format_name),
    )
);

name_schema!(
    /// A job's state.
    JobStateName => names("a job's state", JobState::ALL.map(JobState::as_str))
);

name_schema!(
    /// The `state` filter of `GET /v1/jobs`: a state, or empty for every state.
    JobStateFilter => names(
        "a job's state; empty: every state",
        std::iter::once("").chain(JobState::ALL.map(JobState::as_str)),
    )
);

name_schema!(
    /// A capture time (`params::parse_time` checks the same bounds).
    TimeValue => ObjectBuilder::new()
        .schema_type(Type::Number)
        .minimum(Some(-TIME_LIMIT))
        .maximum(Some(TIME_LIMIT))
        .description(Some(
            "normalised capture time (0..1 spans the training frames; others extrapolate)",
        ))
        .into()
);

name_schema!(
    /// A file's bytes (PLY, NPY, PNG) as a response body.
    BinaryFile => ObjectBuilder::new()
        .schema_type(Type::String)
        .format(Some(SchemaFormat::KnownFormat(KnownFormat::Binary)))
        .into()
);

name_schema!(
    /// The binary files of a trained version, as `GET /v1/scenes/{id}/trained/{file}` names
    /// them (the JSON files have an operation each).
    TrainedBinaryFileName => names(
        "a binary file of the trained version",
        [SCENE_FILE, SPZ_FILE, LABELS_FILE, DEFORMATION_WEIGHTS_FILE],
    )
);

/// A schema written as JSON (in utoipa's own shape, so reading it back does not fail; if it
/// did, the schema would be left open, which tests/openapi_contract.rs would notice).
fn from_json(schema: serde_json::Value) -> RefOr<Schema> {
    serde_json::from_value(schema).unwrap_or_default()
}

fn level_ref() -> serde_json::Value {
    serde_json::json!({"$ref": "#/components/schemas/LevelName"})
}

fn vec3() -> serde_json::Value {
    serde_json::json!({"type": "array", "items": {"type": "number"}, "minItems": 3,
        "maxItems": 3})
}

name_schema!(
    /// One camera of `cameras.json` (`segsplat_method::cameras::SceneCamera`).
    TrainedCamera => from_json(serde_json::json!({
        "type": "object",
        "description": "one frame's pinhole camera, in the scene's world frame and units",
        "required": ["name", "width", "height", "fx", "fy", "cx", "cy", "camera_to_world"],
        "properties": {
            "name": {"type": "string", "description": "the frame's image name in the dataset"},
            "width": {"type": "integer", "minimum": 0},
            "height": {"type": "integer", "minimum": 0},
            "fx": {"type": "number"},
            "fy": {"type": "number"},
            "cx": {"type": "number"},
            "cy": {"type": "number"},
            "camera_to_world": {
                "type": "array", "minItems": 4, "maxItems": 4,
                "items": {"type": "array", "items": {"type": "number"}, "minItems": 4,
                    "maxItems": 4},
                "description": "row-major 4x4, OpenCV axes (x right, y down, z forward)",
            },
            "time": {"type": "number",
                "description": "normalised capture time (dynamic scenes only)"},
        },
    }))
);

name_schema!(
    /// One object of `objects.json`
    /// (`segsplat_method::segment_then_splat::objects::ObjectSummary`).
    TrainedObject => from_json(serde_json::json!({
        "type": "object",
        "required": ["level", "object_id", "gaussian_count", "centroid", "bounds_min",
            "bounds_max", "mean_color"],
        "properties": {
            "level": level_ref(),
            "object_id": {"type": "integer", "minimum": 0},
            "gaussian_count": {"type": "integer", "minimum": 0},
            "centroid": vec3(),
            "bounds_min": vec3(),
            "bounds_max": vec3(),
            "mean_color": vec3(),
        },
    }))
);

name_schema!(
    /// One entry of `skipped_pairs.json`: a frame's object the object loss left out.
    SkippedFramePair => from_json(serde_json::json!({
        "type": "object",
        "required": ["frame_index", "frame_name", "level", "object_id"],
        "properties": {
            "frame_index": {"type": "integer", "minimum": 0},
            "frame_name": {"type": "string"},
            "level": level_ref(),
            "object_id": {"type": "integer", "minimum": 0},
        },
    }))
);

name_schema!(
    /// A worker slot's state, as last reported.
    WorkerStateName => names(
        "a worker slot's state",
        [WorkerState::Idle, WorkerState::Busy, WorkerState::Stopped].map(WorkerState::as_str),
    )
);

#[cfg(test)]
mod tests {
    use super::*;

    use segsplat_vision::language::Granularity;

    fn enum_of<T: PartialSchema>() -> Vec<String> {
        let schema = serde_json::to_value(T::schema()).unwrap_or_default();
        schema["enum"]
            .as_array()
            .map(|values| {
                values
                    .iter()
                    .filter_map(|value| value.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default()
    }

    #[test]
    fn every_listed_name_parses() {
        let granularities = enum_of::<GranularityName>();
        assert_eq!(granularities.len(), 4);
        for name in granularities {
            assert!(name.parse::<Granularity>().is_ok(), "{name}");
        }
        let levels = enum_of::<LevelName>();
        assert_eq!(levels, ["small", "middle", "large"]);
        for name in enum_of::<MaskFormatName>() {
            assert!(
                crate::params::parse_mask_format(Some(&name)).is_ok(),
                "{name}"
            );
        }
        assert_eq!(enum_of::<JobStateName>().len(), 5);
        assert_eq!(enum_of::<WorkerStateName>(), ["idle", "busy", "stopped"]);
    }
}
