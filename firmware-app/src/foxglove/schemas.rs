//! JSON schemas (draft 2020-12) of the messages supine sends to Foxglove, one per [`Topic`].
//!
//! The Foxglove types follow the field names of Foxglove's published message schemas (only the fields supine
//! fills are required); `bytes` fields are base64 strings, marked with `contentEncoding` so that Foxglove decodes
//! them. Built once per recording or server start.

use serde_json::{Value, json};

use super::Topic;

fn time() -> Value {
    json!({
        "type": "object",
        "properties": { "sec": { "type": "integer", "minimum": 0 }, "nsec": { "type": "integer", "minimum": 0 } },
        "required": ["sec", "nsec"]
    })
}

fn xyz() -> Value {
    json!({
        "type": "object",
        "properties": { "x": { "type": "number" }, "y": { "type": "number" }, "z": { "type": "number" } },
        "required": ["x", "y", "z"]
    })
}

fn quaternion() -> Value {
    json!({
        "type": "object",
        "properties": {
            "x": { "type": "number" }, "y": { "type": "number" }, "z": { "type": "number" }, "w": { "type": "number" }
        },
        "required": ["x", "y", "z", "w"]
    })
}

fn pose() -> Value {
    json!({
        "type": "object",
        "properties": { "position": xyz(), "orientation": quaternion() },
        "required": ["position", "orientation"]
    })
}

fn color() -> Value {
    json!({
        "type": "object",
        "properties": {
            "r": { "type": "number" }, "g": { "type": "number" }, "b": { "type": "number" }, "a": { "type": "number" }
        },
        "required": ["r", "g", "b", "a"]
    })
}

fn array_of(items: Value) -> Value {
    json!({ "type": "array", "items": items })
}

fn numbers() -> Value {
    array_of(json!({ "type": "number" }))
}

fn object(title: &str, properties: Value, required: &[&str]) -> Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": properties,
        "required": required,
    })
}

fn sphere() -> Value {
    json!({
        "type": "object",
        "properties": { "pose": pose(), "size": xyz(), "color": color() },
        "required": ["pose", "size", "color"]
    })
}

fn line() -> Value {
    json!({
        "type": "object",
        "properties": {
            "type": { "type": "integer", "description": "0 line strip, 1 line loop, 2 line list" },
            "pose": pose(),
            "thickness": { "type": "number" },
            "scale_invariant": { "type": "boolean" },
            "points": array_of(xyz()),
            "color": color(),
            "colors": array_of(color()),
            "indices": array_of(json!({ "type": "integer", "minimum": 0 }))
        },
        "required": ["type", "pose", "thickness", "scale_invariant", "points", "color"]
    })
}

fn triangles() -> Value {
    json!({
        "type": "object",
        "properties": {
            "pose": pose(),
            "points": array_of(xyz()),
            "color": color(),
            "colors": array_of(color()),
            "indices": array_of(json!({ "type": "integer", "minimum": 0 }))
        },
        "required": ["pose", "points", "color"]
    })
}

fn entity() -> Value {
    let any = array_of(json!({ "type": "object" }));
    json!({
        "type": "object",
        "properties": {
            "timestamp": time(),
            "frame_id": { "type": "string" },
            "id": { "type": "string" },
            "lifetime": time(),
            "frame_locked": { "type": "boolean" },
            "metadata": array_of(json!({
                "type": "object",
                "properties": { "key": { "type": "string" }, "value": { "type": "string" } }
            })),
            "arrows": any, "cubes": any, "spheres": array_of(sphere()), "cylinders": any,
            "lines": array_of(line()), "triangles": array_of(triangles()), "texts": any, "models": any
        },
        "required": ["timestamp", "frame_id", "id", "lifetime", "frame_locked"]
    })
}

/// The JSON schema of `topic`'s messages.
pub fn schema(topic: Topic) -> Value {
    match topic {
        Topic::Depth => object(
            "foxglove.RawImage",
            json!({
                "timestamp": time(),
                "frame_id": { "type": "string" },
                "width": { "type": "integer", "minimum": 0 },
                "height": { "type": "integer", "minimum": 0 },
                "encoding": { "type": "string", "description": "16UC1: little-endian u16 millimetres, 0 = no depth" },
                "step": { "type": "integer", "minimum": 0 },
                "data": { "type": "string", "contentEncoding": "base64" }
            }),
            &[
                "timestamp",
                "frame_id",
                "width",
                "height",
                "encoding",
                "step",
                "data",
            ],
        ),
        Topic::Calibration => object(
            "foxglove.CameraCalibration",
            json!({
                "timestamp": time(),
                "frame_id": { "type": "string" },
                "width": { "type": "integer", "minimum": 0 },
                "height": { "type": "integer", "minimum": 0 },
                "distortion_model": { "type": "string" },
                "D": numbers(),
                "K": numbers(),
                "R": numbers(),
                "P": numbers()
            }),
            &[
                "timestamp",
                "frame_id",
                "width",
                "height",
                "distortion_model",
                "D",
                "K",
                "R",
                "P",
            ],
        ),
        Topic::Scene => object(
            "foxglove.SceneUpdate",
            json!({
                "deletions": array_of(json!({
                    "type": "object",
                    "properties": {
                        "timestamp": time(),
                        "type": { "type": "integer", "description": "0 matching id, 1 all" },
                        "id": { "type": "string" }
                    },
                    "required": ["timestamp", "type", "id"]
                })),
                "entities": array_of(entity())
            }),
            &["deletions", "entities"],
        ),
        Topic::Transforms => object(
            "foxglove.FrameTransforms",
            json!({
                "transforms": array_of(json!({
                    "type": "object",
                    "properties": {
                        "timestamp": time(),
                        "parent_frame_id": { "type": "string" },
                        "child_frame_id": { "type": "string" },
                        "translation": xyz(),
                        "rotation": quaternion()
                    },
                    "required": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"]
                }))
            }),
            &["transforms"],
        ),
        Topic::Packets => object(
            "supine.Packet",
            json!({
                "kind": { "type": "string", "description": "wire message kind (supine wire decode JSON form)" },
                "seq": { "type": "integer", "minimum": 0 },
                "timestamp_us": { "type": "integer", "minimum": 0 }
            }),
            &["kind", "seq", "timestamp_us"],
        ),
        Topic::Tracker => object(
            "supine.TrackerStatus",
            json!({
                "timestamp": time(),
                "frame": { "type": "integer", "minimum": 0 },
                "capture_us": { "type": "integer", "minimum": 0 },
                "state": { "type": ["string", "null"], "description": "tracker state; null when no tracker ran" },
                "packets": { "type": "integer", "minimum": 0 }
            }),
            &["timestamp", "frame", "capture_us", "state", "packets"],
        ),
    }
}

/// [`schema`] as the bytes an MCAP schema record or a WebSocket advertisement carries.
pub fn schema_text(topic: Topic) -> String {
    schema(topic).to_string()
}
