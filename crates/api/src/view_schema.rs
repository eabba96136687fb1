//! The OpenAPI schema of a view ([`ViewRequest`]): one of its two shapes, a dataset frame or a
//! free camera. The struct reads both shapes' fields as options and `ViewRequest::to_view`
//! refuses the mixtures (400); the schema says which combinations those are, so that a client
//! (or schemathesis) never has to find out by trying. A field of the other shape may still be
//! sent as `null`, as the struct accepts.

use std::borrow::Cow;

use serde_json::json;
use utoipa::openapi::RefOr;
use utoipa::openapi::schema::Schema;
use utoipa::{PartialSchema, ToSchema};

use super::masks::ViewRequest;
use super::schema_names::TimeValue;

fn time_property() -> serde_json::Value {
    json!({"oneOf": [{"$ref": format!("#/components/schemas/{}", TimeValue::name())},
        {"type": "null"}]})
}

/// The dataset-frame shape: `frame_index`, optional `max_side` and `time`.
fn frame_view() -> serde_json::Value {
    json!({
        "type": "object",
        "title": "FrameView",
        "description": "One of the scene's frames, optionally scaled down.",
        "additionalProperties": false,
        "required": ["frame_index"],
        "properties": {
            "frame_index": {"type": "integer", "minimum": 0, "maximum": u32::MAX,
                "description": "0-based in dataset order (`cameras.json`); one the scene \
                    does not have is 400 (the scene's frame count is not in the schema)"},
            "max_side": {"type": ["integer", "null"], "minimum": 1, "maximum": u32::MAX,
                "description": "the longest side of the mask in pixels (default and upper \
                    bound: the frame's size, and `query.max_mask_side`)"},
            "time": time_property(),
            "camera_to_world": {"type": "null"},
            "intrinsics": {"type": "null"},
        },
    })
}

/// The free-camera shape: `camera_to_world` and `intrinsics`, optional `time`.
fn pose_view() -> serde_json::Value {
    let row = json!({"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4});
    // The last row is exactly 0 0 0 1 (`pose_camera` compares it exactly); the rotation's
    // orthonormality, which JSON Schema cannot state, is in the description (else 400).
    // `items` (for elements after the four `prefixItems`, which `maxItems` rules out) as a
    // schema, not `false`: client generators (openapi-python-client) do not read boolean
    // schemas, and utoipa's array needs one.
    let last_row = json!({"type": "array", "minItems": 4, "maxItems": 4,
        "items": {"type": "number"},
        "prefixItems": [{"type": "number", "enum": [0]}, {"type": "number", "enum": [0]},
            {"type": "number", "enum": [0]}, {"type": "number", "enum": [1]}]});
    json!({
        "type": "object",
        "title": "PoseView",
        "description": "Any camera, in the scene's world frame and units.",
        "additionalProperties": false,
        "required": ["camera_to_world", "intrinsics"],
        "properties": {
            "camera_to_world": {"type": "array", "minItems": 4, "maxItems": 4, "items": row.clone(),
                "prefixItems": [row.clone(), row.clone(), row, last_row],
                "description": "row-major 4x4, OpenCV axes (x right, y down, z forward). Must \
                    be a rigid transform: the upper-left 3x3 a rotation (orthonormal within \
                    1e-3, determinant +1: no scale, shear or reflection), the last row exactly \
                    0 0 0 1. A pose that fits this schema but is not rigid is refused with 400, \
                    which a JSON Schema cannot express."},
            "intrinsics": {"$ref": "#/components/schemas/PinholeIntrinsics"},
            "time": time_property(),
            "frame_index": {"type": "null"},
            "max_side": {"type": "null"},
        },
    })
}

impl PartialSchema for ViewRequest {
    fn schema() -> RefOr<Schema> {
        let schema = json!({
            "description": "The view to render masks for: a dataset frame or a free camera; \
                either may carry `time` for a dynamic scene.",
            "oneOf": [frame_view(), pose_view()],
        });
        // Written in utoipa's own shape, so this does not fail; if it did, the view would be
        // left unconstrained, which tests/openapi_contract.rs would notice.
        serde_json::from_value(schema).unwrap_or_default()
    }
}

impl ToSchema for ViewRequest {
    fn name() -> Cow<'static, str> {
        Cow::Borrowed("ViewRequest")
    }

    fn schemas(schemas: &mut Vec<(String, RefOr<Schema>)>) {
        schemas.push((TimeValue::name().into(), TimeValue::schema()));
        schemas.push((
            segsplat_service::serving::PinholeIntrinsics::name().into(),
            segsplat_service::serving::PinholeIntrinsics::schema(),
        ));
    }
}
